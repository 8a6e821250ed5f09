#include "vdbsurf/reeb/row_zip.h"

#include <algorithm>
#include <cstddef>
#include <utility>

namespace vdbsurf::reeb {

namespace {

// The vertices a row passes through more than once, each with the index in the other row that
// its last pass ended on (none yet: SIZE_MAX).
std::vector<std::pair<std::uint32_t, std::size_t>> recurring(const std::vector<RowVertex>& row) {
    std::vector<std::uint32_t> ids;
    ids.reserve(row.size());
    for (const RowVertex& v : row) ids.push_back(v.id);
    std::sort(ids.begin(), ids.end());
    std::vector<std::pair<std::uint32_t, std::size_t>> out;
    for (std::size_t k = 1; k < ids.size(); ++k)
        if (ids[k] == ids[k - 1] && (out.empty() || out.back().first != ids[k])) out.emplace_back(ids[k], SIZE_MAX);
    return out;
}

std::size_t* leftAt(std::vector<std::pair<std::uint32_t, std::size_t>>& table, std::uint32_t id) {
    const auto it = std::lower_bound(table.begin(), table.end(), std::make_pair(id, std::size_t(0)));
    return it != table.end() && it->first == id ? &it->second : nullptr;
}

} // namespace

void zipRows(const std::vector<RowVertex>& a, const std::vector<RowVertex>& b, std::vector<std::uint32_t>& tris) {
    std::size_t i = 0, j = 0;
    auto emit = [&](std::uint32_t x, std::uint32_t y, std::uint32_t z) {
        if (x != y && y != z && z != x) tris.insert(tris.end(), {x, y, z});
    };
    // Where a lobe is narrower in u than the other row's spacing, both passes through its saddle
    // would fan to one vertex of the other row, and the edge between the two would border four
    // triangles: before a vertex comes round again onto the vertex its previous pass ended on,
    // the other row advances (the triangles skew; the mesh stays manifold).
    auto aRecurring = recurring(a), bRecurring = recurring(b);
    auto comesRound = [](std::vector<std::pair<std::uint32_t, std::size_t>>& table, std::uint32_t id, std::size_t other) {
        const std::size_t* at = leftAt(table, id);
        return at && *at == other;
    };
    auto advanceA = [&] {
        emit(a[i].id, a[i + 1].id, b[j].id);
        if (std::size_t* at = leftAt(aRecurring, a[i].id)) *at = j;
        ++i;
    };
    auto advanceB = [&] {
        emit(a[i].id, b[j + 1].id, b[j].id);
        if (std::size_t* at = leftAt(bRecurring, b[j].id)) *at = i;
        ++j;
    };
    while (i + 1 < a.size() || j + 1 < b.size()) {
        if (j + 1 == b.size() || (i + 1 < a.size() && a[i + 1].u <= b[j + 1].u)) {
            if (j + 1 < b.size() && comesRound(aRecurring, a[i + 1].id, j)) advanceB();
            advanceA();
        } else {
            if (i + 1 < a.size() && comesRound(bRecurring, b[j + 1].id, i)) advanceA();
            advanceB();
        }
    }
}

} // namespace vdbsurf::reeb
