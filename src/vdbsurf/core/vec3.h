// Small fixed-size vector used across module boundaries, so that modules that do not work on
// volumes (mesh, subdivision, surface fitting) need not include OpenVDB's headers.
#pragma once
#include <cmath>
#include <cstddef>

namespace vdbsurf {

template <typename T>
struct Vec3 {
    T x = 0, y = 0, z = 0;

    constexpr Vec3() = default;
    constexpr Vec3(T x_, T y_, T z_) : x(x_), y(y_), z(z_) {}
    template <typename U>
    constexpr explicit Vec3(const Vec3<U>& o) : x(T(o.x)), y(T(o.y)), z(T(o.z)) {}

    constexpr T& operator[](std::size_t i) { return i == 0 ? x : (i == 1 ? y : z); }
    constexpr T operator[](std::size_t i) const { return i == 0 ? x : (i == 1 ? y : z); }

    constexpr Vec3 operator+(const Vec3& o) const { return {x + o.x, y + o.y, z + o.z}; }
    constexpr Vec3 operator-(const Vec3& o) const { return {x - o.x, y - o.y, z - o.z}; }
    constexpr Vec3 operator-() const { return {-x, -y, -z}; }
    constexpr Vec3 operator*(T s) const { return {x * s, y * s, z * s}; }
    constexpr Vec3 operator/(T s) const { return {x / s, y / s, z / s}; }
    Vec3& operator+=(const Vec3& o) { x += o.x; y += o.y; z += o.z; return *this; }
    Vec3& operator-=(const Vec3& o) { x -= o.x; y -= o.y; z -= o.z; return *this; }
    Vec3& operator*=(T s) { x *= s; y *= s; z *= s; return *this; }
    constexpr bool operator==(const Vec3& o) const { return x == o.x && y == o.y && z == o.z; }
    constexpr bool operator!=(const Vec3& o) const { return !(*this == o); }
};

template <typename T> constexpr Vec3<T> operator*(T s, const Vec3<T>& v) { return v * s; }
template <typename T> constexpr T dot(const Vec3<T>& a, const Vec3<T>& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
template <typename T> constexpr Vec3<T> cross(const Vec3<T>& a, const Vec3<T>& b) {
    return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
template <typename T> T length(const Vec3<T>& v) { return std::sqrt(dot(v, v)); }
template <typename T> Vec3<T> normalized(const Vec3<T>& v) {
    const T l = length(v);
    return l > T(0) ? v / l : Vec3<T>{};
}
template <typename T> Vec3<T> vmin(const Vec3<T>& a, const Vec3<T>& b) {
    return {a.x < b.x ? a.x : b.x, a.y < b.y ? a.y : b.y, a.z < b.z ? a.z : b.z};
}
template <typename T> Vec3<T> vmax(const Vec3<T>& a, const Vec3<T>& b) {
    return {a.x > b.x ? a.x : b.x, a.y > b.y ? a.y : b.y, a.z > b.z ? a.z : b.z};
}
template <typename T> T maxComponent(const Vec3<T>& v) { return v.x > v.y ? (v.x > v.z ? v.x : v.z) : (v.y > v.z ? v.y : v.z); }
// The largest |component|: a scale to divide by before taking a length that could overflow.
template <typename T> T maxAbsComponent(const Vec3<T>& v) { return maxComponent(Vec3<T>{std::fabs(v.x), std::fabs(v.y), std::fabs(v.z)}); }

using Vec3d = Vec3<double>;
using Vec3f = Vec3<float>;
using Vec3i = Vec3<int>;

// Lattice coordinates in order: x, then y, then z (sorted lists of nodes, searched by bisection).
inline bool lessXYZ(const Vec3i& a, const Vec3i& b) {
    return a.x != b.x ? a.x < b.x : a.y != b.y ? a.y < b.y : a.z < b.z;
}

// Axis-aligned box in world units, closed on both ends.
struct Box3 {
    Vec3d min, max;
    Vec3d extent() const { return max - min; }
    double longestSide() const { return maxComponent(extent()); }
    Vec3d center() const { return (min + max) * 0.5; }
    bool contains(const Vec3d& p) const {
        return p.x >= min.x && p.y >= min.y && p.z >= min.z && p.x <= max.x && p.y <= max.y && p.z <= max.z;
    }
    // Corner c of 8: bit 0 picks max.x, bit 1 max.y, bit 2 max.z.
    Vec3d corner(int c) const { return {(c & 1) ? max.x : min.x, (c & 2) ? max.y : min.y, (c & 4) ? max.z : min.z}; }
    // The smallest box holding n points (n > 0).
    static Box3 around(const Vec3d* p, std::size_t n) {
        Box3 b{p[0], p[0]};
        for (std::size_t i = 1; i < n; ++i) b.min = vmin(b.min, p[i]), b.max = vmax(b.max, p[i]);
        return b;
    }
};

} // namespace vdbsurf
