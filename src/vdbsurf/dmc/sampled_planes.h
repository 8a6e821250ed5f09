// The flat faces around a cell of a grid meshed coarser than its voxels, for the sharp pass.
//
// A grid's gradient is a difference of its voxels, so within a voxel and a half of an edge or
// corner of the shape every stencil straddles the kink and the crossing normals there blend the
// faces' normals; the interpolant rounds the kink off too. In a lattice cell a few voxels wide
// that is most of a corner cell's crossings: the planes through them meet off the corner, or the
// third face reads as curvature, and the corner was cut off (40 random rotated boxes, chamfers,
// prisms, pyramids on a grid of voxel H/5 meshed at H: 29 lost a corner by 0.1-1.1 H, where the
// same formulas lose none). Farther out a face's normals are exact and all alike, so the faces
// are found as the tight clusters of surface samples around the cell (normals within a few
// degrees, positions on one plane, spread over an area, not along a line as the blend's are)
// and each of the cell's crossings takes the normal of the face it lies on. (Its position stays:
// moved onto the face's plane too, corners came out exact rather than within 0.04 H, but
// feature points on a box's edges then met crossings beside them in float far from the origin,
// leaving polygons of no area.)
#pragma once
#include "vdbsurf/core/lattice_frame.h"
#include "vdbsurf/field/field.h"

#include <utility>
#include <vector>

namespace vdbsurf {

class SampledPlanes {
public:
    // Only for a field that interpolates samples (Field::sampleSpacing) at least
    // kMinVoxelsPerCell times finer than the lattice (at its own voxel size the blend and the
    // rounding reach beyond the cells around; an exact function's normals are its faces').
    static bool appliesTo(const Field& field, const LatticeFrame& frame);

    SampledPlanes(const Field& field, const LatticeFrame& frame, double iso);

    struct Scratch; // per thread

    // Replaces the normal of each crossing (c[i], n[i], i < count: outward unit normals) that
    // lies on a face found around `cell` by the face's normal. Returns how many changed.
    // Deterministic: a function of the field and the cell alone.
    int snap(const Vec3i& cell, const Vec3d* c, Vec3d* n, int count, Scratch& scratch) const;

private:
    // The crossings (positions, outward normals) of the lattice edges between `nodes`^3 nodes of
    // `frame` from `first`.
    void gather(const LatticeFrame& frame, const Vec3i& first, int nodes, Scratch& scratch) const;

    const Field& mField;
    LatticeFrame mFrame, mSampleFrame;
    double mIso;
    double mOutward; // +1 where the gradient points out (level sets), -1 (fog)
};

struct SampledPlanes::Scratch {
    std::vector<double> values;
    std::vector<Vec3d> points, normals;
    std::vector<int> face;
    std::vector<std::size_t> members; // of the cluster being formed
    std::vector<std::pair<int, int>> order; // (-support, sample)
};

} // namespace vdbsurf
