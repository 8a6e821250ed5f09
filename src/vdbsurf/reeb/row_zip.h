// Stitching two rows of a patch's tessellation into triangles. Owns the rule that keeps the
// stitch manifold where a row passes through one vertex more than once (a saddle between lobes).
#pragma once
#include <cstdint>
#include <vector>

namespace vdbsurf::reeb {

struct RowVertex {
    std::uint32_t id;
    double u;
};

// Triangles (three indices each, appended to tris) between two rows that run from u = 0 to
// u = 1 and close (first and last vertex the same), advancing along whichever row's next vertex
// comes first in u. A vertex may recur in a row (an end row passes through its saddle once per
// lobe); each pass meets other vertices of the other row than the previous one, so no edge
// borders more than two triangles.
void zipRows(const std::vector<RowVertex>& a, const std::vector<RowVertex>& b, std::vector<std::uint32_t>& tris);

} // namespace vdbsurf::reeb
