// Which side of the iso a lattice node lies on at rest, sampled once per node: the topology
// checks after the thin search and the sharp pass ask for the same few nodes many times.
#pragma once
#include "vdbsurf/core/lattice_frame.h"
#include "vdbsurf/core/vec3.h"
#include "vdbsurf/field/field.h"

#include <map>
#include <tuple>

namespace vdbsurf {

class RestSides {
public:
    RestSides(const Field& field, const LatticeFrame& frame, double iso) : mField(field), mFrame(frame), mIso(iso), mSide(field.inside()) {}
    bool inside(const Vec3i& n) {
        const auto key = std::make_tuple(n.x, n.y, n.z);
        const auto it = mKnown.find(key);
        if (it != mKnown.end()) return it->second;
        return mKnown[key] = isInside(mField.value(mFrame.nodeWorld(n)), mIso, mSide);
    }

private:
    const Field& mField;
    const LatticeFrame& mFrame;
    double mIso;
    Inside mSide;
    std::map<std::tuple<int, int, int>, bool> mKnown;
};

} // namespace vdbsurf
