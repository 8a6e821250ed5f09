#include "support/shapes.h"

#include <cmath>

namespace vdbsurf::test {

Mesh cubeMesh() {
    Mesh m;
    m.points = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
    m.addPolygon({0, 3, 2, 1});
    m.addPolygon({4, 5, 6, 7});
    m.addPolygon({0, 1, 5, 4});
    m.addPolygon({1, 2, 6, 5});
    m.addPolygon({2, 3, 7, 6});
    m.addPolygon({3, 0, 4, 7});
    return m;
}

Mesh pyramidMesh() {
    Mesh m;
    m.points = {{-1, -1, 0}, {1, -1, 0}, {1, 1, 0}, {-1, 1, 0}, {0.1f, -0.2f, 1.5f}};
    m.addPolygon({0, 3, 2, 1});
    m.addPolygon({0, 1, 4});
    m.addPolygon({1, 2, 4});
    m.addPolygon({2, 3, 4});
    m.addPolygon({3, 0, 4});
    return m;
}

Mesh pentagonalPrismMesh() {
    Mesh m;
    for (int z = 0; z < 2; ++z)
        for (int k = 0; k < 5; ++k) {
            const double a = 2 * M_PI * k / 5;
            m.points.emplace_back(float(std::cos(a)), float(std::sin(a)), float(z * 1.3));
        }
    m.addPolygon({4, 3, 2, 1, 0});
    m.addPolygon({5, 6, 7, 8, 9});
    for (std::uint32_t k = 0; k < 5; ++k) m.addPolygon({k, (k + 1) % 5, (k + 1) % 5 + 5, k + 5});
    return m;
}

Mesh octahedronMesh() {
    Mesh m;
    m.points = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
    const std::uint32_t ring[4] = {0, 2, 1, 3};
    for (int k = 0; k < 4; ++k) {
        m.addPolygon({ring[k], ring[(k + 1) % 4], 4});
        m.addPolygon({ring[(k + 1) % 4], ring[k], 5});
    }
    return m;
}

Mesh mixedClosedMesh() {
    // A skewed cube: the bottom fanned into 5 triangles around a centre vertex, the top into two
    // triangles and a quad around an inner vertex, the front a pentagon through a vertex on its
    // bottom edge. Triangles, quads and a pentagon; valences 3 to 6.
    Mesh m;
    m.points = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {0, 0, 1}, {1, 0, 1}, {1, 1, 1.2f}, {0, 1, 1},
                {0.45f, 0.55f, -0.3f}, {0.6f, 0.4f, 1.3f}, {0.4f, 0, 0}};
    m.addPolygon({0, 3, 8});
    m.addPolygon({3, 2, 8});
    m.addPolygon({2, 1, 8});
    m.addPolygon({1, 10, 8});
    m.addPolygon({10, 0, 8});
    m.addPolygon({4, 5, 9});
    m.addPolygon({5, 6, 9});
    m.addPolygon({6, 7, 4, 9});
    m.addPolygon({0, 10, 1, 5, 4});
    m.addPolygon({1, 2, 6, 5});
    m.addPolygon({2, 3, 7, 6});
    m.addPolygon({3, 0, 4, 7});
    return m;
}

Mesh quadTorusMesh(int nu, int nv, double R, double r) {
    Mesh m;
    for (int i = 0; i < nu; ++i)
        for (int j = 0; j < nv; ++j) {
            const double a = 2 * M_PI * i / nu, b = 2 * M_PI * j / nv;
            m.points.emplace_back(float((R + r * std::cos(b)) * std::cos(a)), float((R + r * std::cos(b)) * std::sin(a)), float(r * std::sin(b)));
        }
    auto id = [&](int i, int j) { return std::uint32_t(((i + nu) % nu) * nv + (j + nv) % nv); };
    for (int i = 0; i < nu; ++i)
        for (int j = 0; j < nv; ++j) m.addPolygon({id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)});
    return m;
}

Mesh openGridMesh(int n) {
    Mesh m;
    for (int j = 0; j <= n; ++j)
        for (int i = 0; i <= n; ++i) m.points.emplace_back(float(i) + 0.1f * float((i * 7 + j * 3) % 5), float(j), 0.2f * float((i * j) % 3));
    auto id = [&](int i, int j) { return std::uint32_t(j * (n + 1) + i); };
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) m.addPolygon({id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)});
    return m;
}

Mesh openCubeMesh() {
    Mesh c = cubeMesh();
    Mesh m;
    m.points = c.points;
    for (std::size_t f = 0; f < c.polygonCount(); ++f)
        if (f != 1) m.addPolygon(c.polygon(f), c.polygonSize(f));
    return m;
}

Mesh pointPerCorner(const Mesh& mesh) {
    Mesh m;
    for (std::size_t f = 0; f < mesh.polygonCount(); ++f) {
        std::vector<std::uint32_t> vs;
        for (std::uint32_t k = 0; k < mesh.polygonSize(f); ++k) {
            vs.push_back(std::uint32_t(m.points.size()));
            m.points.push_back(mesh.points[mesh.polygon(f)[k]]);
        }
        m.addPolygon(vs.data(), vs.size());
    }
    return m;
}

Mesh triangleFanDisc(int n) {
    Mesh m;
    m.points.emplace_back(0.f, 0.f, 0.3f);
    for (int k = 0; k < n; ++k) {
        const double a = 2 * M_PI * k / n;
        m.points.emplace_back(float(std::cos(a)), float(std::sin(a) * 0.8), 0.f);
    }
    for (int k = 0; k < n; ++k) m.addPolygon({0, std::uint32_t(1 + k), std::uint32_t(1 + (k + 1) % n)});
    return m;
}

} // namespace vdbsurf::test
