#include "vdbsurf/dmc/sampled_planes.h"

#include <algorithm>
#include <cmath>

namespace vdbsurf {

namespace {

// Below this many voxels a cell, the blend and the rounding at a kink reach past the cells
// around (a voxel and a half of gradient stencil, and the interpolant's rounding, which a field
// check at the feature's point must tolerate).
constexpr double kMinVoxelsPerCell = 2.5;
// Surface samples: the crossings of a lattice of half the cell's spacing over the cell and the
// cells beside it (7 nodes a side).
constexpr int kSamplesPerCell = 2, kSampleNodes = 3 * kSamplesPerCell + 1;
// A face: at least this many samples whose normals agree within this cosine (0.6 degrees: a
// face's exact normals agree to rounding, a blend turns by 90 degrees over a few voxels; at 2.6
// degrees and 0.02 cells the armadillo's gently curved patches at 2.5 voxels a cell passed for
// faces in 3,182 cells) and that lie on one plane within this share of a cell, spread over an
// area (the root of their positions' smaller in-plane variance at least this share of a cell:
// samples at one distance from a straight kink blend alike, but lie on a line along it).
constexpr int kMinSupport = 5;
constexpr double kTightCosine = 0.99995, kOnPlane = 0.005, kMinSpread = 0.1;
// The first look: two crossings of the cells around at least this far apart (in cells) on one
// flat face.
constexpr double kApart = 0.5;
// Clusters examined per cell at most (faces, and the lines of like blends that are not).
constexpr int kMaxClusters = 8;
// A crossing lies on a face when within this share of a cell of its plane (a kink's rounding
// pulls crossings in by a fraction of a voxel) and its normal within this cosine of the face's
// (the blend at a kink turns part way from one face's normal to the other's).
constexpr double kSnapDistance = 0.2, kSnapCosine = 0.7;

struct Face {
    Vec3d normal;
    double offset; // normal · x on the face
};

} // namespace

bool SampledPlanes::appliesTo(const Field& field, const LatticeFrame& frame) {
    const auto voxel = field.sampleSpacing();
    return voxel && *voxel > 0 && frame.h >= kMinVoxelsPerCell * *voxel;
}

SampledPlanes::SampledPlanes(const Field& field, const LatticeFrame& frame, double iso)
    : mField(field), mFrame(frame), mSampleFrame{frame.origin, frame.h / kSamplesPerCell}, mIso(iso),
      mOutward(field.inside() == Inside::Below ? 1.0 : -1.0) {}

void SampledPlanes::gather(const LatticeFrame& frame, const Vec3i& first, int nodes, Scratch& s) const {
    const int N = nodes;
    const Inside side = mField.inside();
    s.values.resize(std::size_t(N * N * N));
    mField.sampleNodes(frame, first, Vec3i(N, N, N), nullptr, s.values.data());
    s.points.clear();
    s.normals.clear();
    auto at = [&](int x, int y, int z) { return s.values[std::size_t(x + N * (y + N * z))]; };
    for (int z = 0; z < N; ++z)
        for (int y = 0; y < N; ++y)
            for (int x = 0; x < N; ++x) {
                const double va = at(x, y, z);
                const bool in = isInside(va, mIso, side);
                const Vec3i pa(x, y, z);
                for (int axis = 0; axis < 3; ++axis) {
                    Vec3i pb = pa;
                    pb[axis] += 1;
                    if (pb[axis] >= N) continue;
                    const double vb = at(pb.x, pb.y, pb.z);
                    if (isInside(vb, mIso, side) == in) continue;
                    const Vec3d a = frame.nodeWorld(first + pa), b = frame.nodeWorld(first + pb);
                    // Linear along the edge: exact where the voxels are a plane's distances,
                    // which are the samples that count (refined, the pass took twice as long).
                    const Vec3d p = a + (b - a) * ((mIso - va) / (vb - va));
                    const Vec3d g = mField.gradient(p);
                    const double len = length(g);
                    if (!(len > 0) || !std::isfinite(len)) continue;
                    s.points.push_back(p);
                    s.normals.push_back(g * (mOutward / len));
                }
            }
}

int SampledPlanes::snap(const Vec3i& cell, const Vec3d* c, Vec3d* n, int count, Scratch& s) const {
    const double h = mFrame.h;
    auto tight = [&](std::size_t i, std::size_t j) { // (the normals first: most pairs fail there)
        return dot(s.normals[i], s.normals[j]) >= kTightCosine && std::fabs(dot(s.normals[i], s.points[j] - s.points[i])) <= kOnPlane * h;
    };
    // First the crossings of the cells around alone: where no two of them half a cell apart or
    // more lie on one flat face (a curved surface: the armadillo at a few voxels a cell), there is
    // nothing to find, at a tenth of the cost. (Two crossings beside one node agree anywhere.)
    gather(mFrame, cell - Vec3i(1, 1, 1), 4, s);
    bool flat = false;
    for (std::size_t i = 0; i < s.points.size() && !flat; ++i)
        for (std::size_t j = i + 1; j < s.points.size() && !flat; ++j)
            flat = tight(i, j) && length(s.points[i] - s.points[j]) >= kApart * h;
    if (!flat) return 0;
    gather(mSampleFrame, (cell - Vec3i(1, 1, 1)) * kSamplesPerCell, kSampleNodes, s);

    const std::size_t m = s.points.size();
    const std::vector<Vec3d>& p = s.points;
    const std::vector<Vec3d>& nn = s.normals;
    s.face.assign(m, -1); // -1 free, else the cluster that took the sample
    // Seeds in order of their support among all samples (counted once: the support among the
    // samples still free is counted again for the seed alone).
    s.order.clear();
    for (std::size_t i = 0; i < m; ++i) {
        int support = 0;
        for (std::size_t j = 0; j < m; ++j) support += tight(i, j);
        if (support >= kMinSupport) s.order.emplace_back(-support, int(i));
    }
    std::sort(s.order.begin(), s.order.end());
    Face faces[kMaxClusters];
    int faceCount = 0, cluster = 0;
    for (const auto& candidate : s.order) {
        if (cluster == kMaxClusters) break;
        const std::size_t seed = std::size_t(candidate.second);
        if (s.face[seed] >= 0) continue;
        s.members.clear();
        Vec3d sum, centroid;
        for (std::size_t j = 0; j < m; ++j)
            if (s.face[j] < 0 && tight(seed, j)) sum += nn[j], centroid += p[j], s.members.push_back(j);
        const double k = double(s.members.size());
        if (k < kMinSupport) continue;
        const Vec3d normal = normalized(sum);
        centroid = centroid / k;
        // The samples' spread across the plane: the smaller eigenvalue of their 2x2 covariance.
        const Vec3d u = normalized(std::fabs(normal.x) < 0.6 ? cross(normal, Vec3d(1, 0, 0)) : cross(normal, Vec3d(0, 1, 0)));
        const Vec3d w = cross(normal, u);
        double uu = 0, uw = 0, ww = 0;
        for (const std::size_t j : s.members) {
            const Vec3d q = p[j] - centroid;
            const double a = dot(u, q), b = dot(w, q);
            uu += a * a, uw += a * b, ww += b * b;
            s.face[j] = cluster;
        }
        uu /= k, uw /= k, ww /= k;
        const double half = 0.5 * (uu - ww), least = 0.5 * (uu + ww) - std::sqrt(half * half + uw * uw);
        if (least >= kMinSpread * kMinSpread * h * h) faces[faceCount++] = {normal, dot(normal, centroid)};
        ++cluster;
    }

    int changed = 0;
    for (int i = 0; i < count; ++i) {
        int pick = -1;
        double agree = kSnapCosine;
        for (int f = 0; f < faceCount; ++f) {
            const double d = dot(n[i], faces[f].normal);
            if (d >= agree && std::fabs(dot(faces[f].normal, c[i]) - faces[f].offset) <= kSnapDistance * h) agree = d, pick = f;
        }
        if (pick < 0) continue;
        n[i] = faces[pick].normal;
        ++changed;
    }
    return changed;
}

} // namespace vdbsurf
