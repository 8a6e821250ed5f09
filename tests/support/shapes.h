// Small polygon meshes with known structure for subdivision and topology tests.
#pragma once
#include "vdbsurf/mesh/mesh.h"

namespace vdbsurf::test {

Mesh cubeMesh();               // 6 quads, valence-3 corners (extraordinary)
Mesh pyramidMesh();            // 4 triangles and a quad
Mesh pentagonalPrismMesh();    // 2 pentagons and 5 quads
Mesh octahedronMesh();         // 8 triangles, valence 4
Mesh mixedClosedMesh();        // triangles, quads and a pentagon; valences 3 to 6
Mesh quadTorusMesh(int u, int v, double R, double r); // u x v quads, genus 1
Mesh openGridMesh(int n);      // n x n quads in the plane z = 0, with a boundary
Mesh openCubeMesh();           // the cube without its top face
Mesh triangleFanDisc(int n);   // n triangles around a centre, boundary polygon of n edges
// The same polygons with a point of their own at every corner, as a file written per corner
// (or split at seams) stores them: open along every edge.
Mesh pointPerCorner(const Mesh& mesh);

} // namespace vdbsurf::test
