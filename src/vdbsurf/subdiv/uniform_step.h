// The √2 step that refines every face, written straight into a second halfedge mesh. When
// every face is refined the new connectivity is a fixed function of the old one — one new edge
// per old halfedge (its spoke pair, or the kept boundary edge), one new face per old edge (the
// merged quad, or the fan triangle on a kept boundary edge) — so new elements are numbered
// arithmetically and each is written once, in parallel, with no partner search and no polygon
// lists. It makes the same surface as the general (adaptive) step in sqrt2_subdivision.cpp,
// with the new faces in old-edge order. Internal to the subdiv module.
#pragma once
#include "vdbsurf/subdiv/halfedge_mesh.h"

namespace vdbsurf::subdiv {

// One √2 step of `from` (odd: Catmull-Clark face, edge and vertex points; even: stored points as
// face points, no vertex update) into `to`, whose connectivity and properties are replaced. A
// merged face's tag combines its two parents' tags by bitwise or when `mergeByOr`, else by max.
void refineEveryFace(const HalfedgeMesh& from, const FaceProperties& props, bool odd, bool mergeByOr, HalfedgeMesh& to);

} // namespace vdbsurf::subdiv
