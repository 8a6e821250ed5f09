// √2-subdivision (seed 001): Catmull-Clark split into two steps that share one topological
// operation, so refinement can stop at half levels and differ across the mesh without cracks.
//
//   odd step  — face points (vertex average) become vertices; each n-gon is fanned into n
//               triangles; Catmull-Clark edge points are stored on the old edges; old vertices
//               move by the paper's eq. (1); every old edge with refined faces on both sides is
//               removed, so its two triangles merge into a quad that keeps the edge point.
//   even step — the same fan-and-remove on the quads, with the stored edge point as face point
//               and no vertex update. Two steps equal one Catmull-Clark step.
//
// Boundaries (not in the paper): boundary edges are never removed; the odd step moves boundary
// vertices by the crease rule (6v + a + b) / 8 and stores the boundary edge's midpoint on the
// triangle beside it; the even step splits that boundary edge at the midpoint instead of fanning
// the triangle. Two steps then equal OpenSubdiv's Catmull-Clark with edge-only boundary
// interpolation.
//
// Adaptivity (paper §3.5): a step refines only the faces asked for; an edge between a refined
// and an unrefined face is kept, so its fan triangle stays and fills the transition. Step i may
// refine only faces made by step i − 1 (or, for step 1, input faces): a face left alone once is
// final. A vertex moves only when every face around it is refined in that step, so the surface of
// a coarser neighbour is never pulled by a finer level's rule. The result is closed, manifold and
// consistently oriented whenever the input is, for any choice of faces.
#pragma once
#include "vdbsurf/core/vec3.h"
#include "vdbsurf/mesh/mesh.h"

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace vdbsurf {

class Sqrt2Subdivider {
public:
    // How the per-face tag of a face merged from two refined faces is formed.
    enum class TagMerge { Max, BitOr };

    // Throws Error naming inputName when an edge has three or more polygons or two polygons
    // disagree on orientation. A vertex where separate fans of polygons meet is split into one
    // vertex per fan (they then part as the fans are smoothed); see splitVertices().
    Sqrt2Subdivider(const Mesh& mesh, const std::string& inputName);
    ~Sqrt2Subdivider();
    Sqrt2Subdivider(const Sqrt2Subdivider&) = delete;
    Sqrt2Subdivider& operator=(const Sqrt2Subdivider&) = delete;

    int stepsDone() const;
    std::size_t splitVertices() const; // vertex copies made for non-manifold vertices
    std::size_t faceCount() const;
    std::size_t vertexCount() const;

    // Per-face tags (current face order): children inherit their face's tag, a merged face
    // combines its two parents' tags. Callers use them for target depths or view flags.
    void setTags(const std::vector<std::uint32_t>& tags, TagMerge merge);
    std::vector<std::uint32_t> tags() const;

    // A step that refines every face takes a faster path (uniform_step.h) making the same surface
    // with the new faces in another order; true sends every step through the general path, for
    // tests and benchmarks that compare the two.
    void setAlwaysGeneral(bool general);

    // One √2 step refining the faces whose entry is non-zero (current face order), or all.
    // Throws Error naming the input, before any work, when the refined mesh would take more
    // than the memory limit (kBytesPerFace a polygon).
    void step(const std::vector<std::uint8_t>& refine);
    void step();

    // The polygons a step refining these faces makes: the unrefined ones, and one per edge
    // beside a refined face (a quad where both sides are refined, else the fan triangle that
    // stays) — exact on closed meshes; on open ones the even step's boundary splits make up to
    // one fewer per boundary edge. What the memory check counts.
    std::size_t facesAfterStep(const std::vector<std::uint8_t>& refine) const;
    // Throws the same Error before any work when `steps` more uniform steps would pass the
    // limit: every step makes one polygon per edge, so the count after them is known now.
    void checkUniformSteps(int steps) const;

    // Bytes a refined mesh may take, as estimated per polygon; 0 (the default): 80 % of the
    // memory free when the subdivider was made — past it the kernel would kill the process.
    void setMemoryLimit(double bytes);
    // What a polygon costs at the peak of a step and its output (both levels' halfedges, the
    // Mesh handed out): measured 195 bytes on quad meshes; the estimate errs low, so a mesh that
    // may just fit is still made.
    static constexpr double kBytesPerFace = 160;

    Mesh mesh() const;                  // float positions, for writing
    std::vector<Vec3d> positions() const; // double positions, for comparisons
    // Vertices of face f in order; for the view-dependent refiner's per-face tests.
    void faceCorners(std::size_t f, std::vector<Vec3d>& out) const;
    // Per edge, its two faces (−1 for a boundary side) and its two vertices, for silhouette tests.
    void edgeFaces(std::vector<std::pair<std::int64_t, std::int64_t>>& faces, std::vector<std::pair<std::uint32_t, std::uint32_t>>& vertices) const;
    // Vertex indices of face f.
    void faceVertices(std::size_t f, std::vector<std::uint32_t>& out) const;

private:
    struct Impl;
    std::unique_ptr<Impl> mImpl;
};

// Convenience: `steps` uniform √2 steps (2 per Catmull-Clark level).
Mesh subdivideUniform(const Mesh& mesh, int steps, const std::string& inputName);

// Adaptive refinement to a per-face target depth in √2 steps (one entry per input polygon).
Mesh subdivideAdaptive(const Mesh& mesh, const std::vector<int>& targetSteps, const std::string& inputName);

} // namespace vdbsurf
