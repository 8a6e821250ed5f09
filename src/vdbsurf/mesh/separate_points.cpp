#include "vdbsurf/mesh/separate_points.h"

#include "vdbsurf/core/fixed_chunks.h"

#include <tbb/parallel_sort.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <tuple>

namespace vdbsurf {

namespace {

bool isFinite(const Vec3f& p) { return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z); }

// p moved `share` of the way to c, as a float that differs from p (one float step along the
// direction's largest component where the share rounds away).
Vec3f towards(const Vec3f& p, const Vec3d& c, double share) {
    const Vec3d from(p);
    const Vec3d d = c - from;
    Vec3f q(from + d * share);
    if (q == p) {
        int axis = 0;
        for (int a = 1; a < 3; ++a)
            if (std::abs(d[a]) > std::abs(d[axis])) axis = a;
        q[axis] = std::nextafter(p[axis], float(c[axis]));
    }
    return q;
}

} // namespace

std::size_t separateCoincidentPoints(Mesh& mesh, std::vector<std::uint32_t> suspects) {
    suspects.erase(std::remove_if(suspects.begin(), suspects.end(),
                                  [&](std::uint32_t v) { return v >= mesh.points.size() || !isFinite(mesh.points[v]); }),
                   suspects.end());
    // By position, then by index (one parallel sort: a repeat then sits beside itself).
    tbb::parallel_sort(suspects.begin(), suspects.end(), [&](std::uint32_t a, std::uint32_t b) {
        const Vec3f &p = mesh.points[a], &q = mesh.points[b];
        return std::tie(p.x, p.y, p.z, a) < std::tie(q.x, q.y, q.z, b);
    });
    suspects.erase(std::unique(suspects.begin(), suspects.end()), suspects.end());
    // Runs of one position, two vertices or more: [start, end) into `grouped`.
    std::vector<std::uint32_t> grouped;
    std::vector<std::pair<std::size_t, std::size_t>> groups;
    for (std::size_t i = 0; i < suspects.size();) {
        std::size_t j = i + 1;
        while (j < suspects.size() && mesh.points[suspects[j]] == mesh.points[suspects[i]]) ++j;
        if (j - i > 1) {
            groups.emplace_back(grouped.size(), grouped.size() + (j - i));
            grouped.insert(grouped.end(), suspects.begin() + std::ptrdiff_t(i), suspects.begin() + std::ptrdiff_t(j));
        }
        i = j;
    }
    if (groups.empty()) return 0;

    // Each grouped vertex's neighbours along its polygons' edges, summed in polygon order. The
    // grouped vertices are few and the mesh may be large: its indices are scanned for them in
    // parallel over fixed chunks (a hit's polygon found from the offsets), and the hits added up
    // in index order, so the sums have the same bits at any thread count.
    // (A bit a vertex: small enough to stay in cache while the indices stream past.)
    std::vector<std::uint64_t> isGrouped((mesh.points.size() + 63) / 64, 0);
    for (const std::uint32_t v : grouped) isGrouped[v >> 6] |= std::uint64_t(1) << (v & 63);
    std::vector<std::pair<std::uint32_t, std::uint32_t>> slotOf; // (vertex, k), by vertex
    for (std::size_t k = 0; k < grouped.size(); ++k) slotOf.emplace_back(grouped[k], std::uint32_t(k));
    std::sort(slotOf.begin(), slotOf.end());
    constexpr std::size_t kChunk = 1 << 16;
    using Hits = std::vector<std::pair<std::uint32_t, std::uint32_t>>; // (k, a neighbour)
    std::vector<Hits> found(fixedChunkCount(mesh.indices.size(), kChunk));
    forEachFixedChunk(mesh.indices.size(), kChunk, [&](std::size_t c, std::size_t b, std::size_t e) {
        for (std::size_t i = b; i < e; ++i) {
            const std::uint32_t v = mesh.indices[i];
            if (!(isGrouped[v >> 6] >> (v & 63) & 1)) continue;
            const std::uint32_t k = std::lower_bound(slotOf.begin(), slotOf.end(), std::make_pair(v, std::uint32_t(0)))->second;
            const auto after = std::upper_bound(mesh.offsets.begin(), mesh.offsets.end(), std::uint32_t(i));
            const std::size_t f = std::size_t(after - mesh.offsets.begin()) - 1;
            const std::uint32_t first = mesh.offsets[f], n = mesh.polygonSize(f), at = std::uint32_t(i) - first;
            const std::uint32_t* p = mesh.polygon(f);
            for (const std::uint32_t w : {p[at > 0 ? at - 1 : n - 1], p[at + 1 < n ? at + 1 : 0]})
                if (mesh.points[w] != mesh.points[p[at]]) found[c].emplace_back(k, w); // (else another copy, or a collapsed edge)
        }
    });
    std::vector<Vec3d> sum(grouped.size(), Vec3d(0, 0, 0));
    std::vector<std::uint32_t> count(grouped.size(), 0);
    for (const auto& chunk : found)
        for (const auto& [k, w] : chunk) {
            sum[k] += Vec3d(mesh.points[w]);
            ++count[k];
        }

    std::size_t moved = 0;
    std::vector<Vec3f> taken;
    for (const auto& [b, e] : groups) {
        const Vec3f at = mesh.points[grouped[b]];
        taken.assign(1, at);
        // Members with no neighbour elsewhere (unused, or all of whose polygons lie at this point)
        // stay; if several would, one of them is no better than another.
        for (std::size_t k = b; k < e; ++k) {
            if (count[k] == 0) continue;
            const Vec3d centroid = sum[k] / double(count[k]);
            Vec3f q = towards(at, centroid, kSeparationShare);
            // (Symmetric neighbours, or a share that rounds to the same float: further, then a
            // float step at a time.)
            for (int step = 2; step < 64 && std::find(taken.begin(), taken.end(), q) != taken.end(); ++step)
                q = step <= 8 ? towards(at, centroid, kSeparationShare * step)
                              : Vec3f(std::nextafter(q.x, std::numeric_limits<float>::infinity()), q.y, q.z);
            taken.push_back(q);
            mesh.points[grouped[k]] = q;
            ++moved;
        }
    }
    return moved;
}

} // namespace vdbsurf
