// Disjoint sets over dense indices, for grouping corners into fans and mesh pieces into units.
#pragma once
#include <cstdint>
#include <numeric>
#include <vector>

namespace vdbsurf {

class UnionFind {
public:
    explicit UnionFind(std::size_t n) : mParent(n) { std::iota(mParent.begin(), mParent.end(), std::uint32_t(0)); }
    std::uint32_t find(std::uint32_t x) {
        while (mParent[x] != x) x = mParent[x] = mParent[mParent[x]];
        return x;
    }
    // The smaller root wins, so roots do not depend on the order of the unions.
    void unite(std::uint32_t a, std::uint32_t b) {
        a = find(a);
        b = find(b);
        if (a < b) mParent[b] = a;
        else if (b < a) mParent[a] = b;
    }
    std::size_t size() const { return mParent.size(); }

private:
    std::vector<std::uint32_t> mParent;
};

} // namespace vdbsurf
