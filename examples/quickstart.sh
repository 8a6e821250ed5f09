#!/usr/bin/env bash
# The first things a new user runs: mesh a formula, turn the mesh into a VDB level set, look at
# that file, and mesh it back, the way a pipeline would mesh a .vdb from disk.
#   examples/quickstart.sh BUILD/bin/vdbsurf OUT_FOLDER
set -euo pipefail
vdbsurf=${1:?usage: quickstart.sh path/to/vdbsurf out-folder}
out=${2:?usage: quickstart.sh path/to/vdbsurf out-folder}
here=$(cd "$(dirname "$0")" && pwd)
mkdir -p "$out"

# A torus knot of blobs: a formula, negative inside, read from examples/formulas/.
formula=$(grep -v '^#' "$here/formulas/twisted_torus.txt" | tr -d '\n')
echo "== 1. mesh a formula (examples/formulas/twisted_torus.txt)"
"$vdbsurf" mesh --expr "$formula" --bbox -1.6,-1.6,-0.8,1.6,1.6,0.8 --voxel-size 0.02 \
  -o "$out/twisted_torus.obj" --stats "$out/twisted_torus_stats.json"

echo "== 2. the same surface as an OpenVDB level set (OpenVDB meshToVolume)"
"$vdbsurf" -q mesh --expr "$formula" --bbox -1.6,-1.6,-0.8,1.6,1.6,0.8 --voxel-size 0.02 \
  -o "$out/twisted_torus.vdb"

echo "== 3. what the .vdb holds"
"$vdbsurf" info "$out/twisted_torus.vdb"

echo "== 4. mesh the .vdb, as from any vdb_tool / Houdini / Blender cache, at a coarser spacing"
"$vdbsurf" mesh "$out/twisted_torus.vdb" -o "$out/twisted_torus_from_vdb.ply" --voxel-size 0.04

echo "== 5. a blobby density scene (examples/scenes/blobby.json): meshed directly, then rasterized sparsely"
"$vdbsurf" mesh "$here/scenes/blobby.json" -o "$out/blobby.obj"
"$vdbsurf" rasterize "$here/scenes/blobby.json" -o "$out/blobby.vdb"

echo "== 6. move the head (primitive 1, as info numbers them): only the leaves it touches are recomputed"
"$vdbsurf" info "$out/blobby.vdb"
"$vdbsurf" edit "$out/blobby.vdb" --set 1.center=1.25,0.6,0.1 -o "$out/blobby_moved.vdb" --scene-out "$out/blobby_moved.json"
"$vdbsurf" mesh "$out/blobby_moved.vdb" -o "$out/blobby_moved.obj"

echo "== 7. refine a coarse mesh of the scene by sqrt2-subdivision: uniformly, then for a camera (POV-Ray scene)"
"$vdbsurf" -q mesh "$here/scenes/blobby.json" -o "$out/blobby_coarse.obj" --voxel-size 0.1
"$vdbsurf" subdivide "$out/blobby_coarse.obj" -o "$out/blobby_smooth.obj" --levels 2
"$vdbsurf" subdivide "$out/blobby_coarse.obj" -o "$out/blobby_view.pov" \
  --camera-pos 2.4,2.0,6.4 --camera-target 0.15,-0.05,0 --fov 40 --image 640,480
if command -v povray > /dev/null; then
  (cd "$out" && povray +Iblobby_view.pov +Oblobby_view.png +W640 +H480 +A0.3 -D -V > /dev/null 2>&1) &&
    echo "rendered $out/blobby_view.png with POV-Ray"
fi

echo "== 8. B-spline patches of the scene, laid out by its Reeb graph along y (up) (OBJ free-form surfaces)"
"$vdbsurf" -q mesh "$here/scenes/blobby.json" -o "$out/blobby_h05.obj" --voxel-size 0.05
"$vdbsurf" patches "$out/blobby_h05.obj" -o "$out/blobby_patches.obj" --reeb "$out/blobby_reeb.json" \
  --preview "$out/blobby_patches.pov" --axis y
if command -v povray > /dev/null; then
  (cd "$out" && povray +Iblobby_patches.pov +Oblobby_patches.png +W640 +H480 +A0.3 -D -V > /dev/null 2>&1) &&
    echo "rendered $out/blobby_patches.png with POV-Ray"
fi

echo
echo "results are in $out:"
ls -l "$out" | awk 'NR > 1 {print "  " $NF "  (" $5 " bytes)"}'
