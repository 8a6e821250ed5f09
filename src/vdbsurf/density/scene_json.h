// Scene files: the JSON form of a density scene (schema in the README), read with every
// mistake reported as one Error naming the file, the primitive and the field; and written back.
#pragma once
#include "vdbsurf/density/scene.h"

#include <string>

namespace vdbsurf {

// source: the file name used in messages.
DensityScene parseSceneText(const std::string& text, const std::string& source);
DensityScene readSceneFile(const std::string& path);

// One primitive's JSON, checked as a scene file's primitives are and numbered `index` in
// messages: for adding it to a scene (alone it may subtract; the scene it joins is checked whole).
Primitive parsePrimitiveText(const std::string& text, std::size_t index, const std::string& source);

// A core's name in scene files: "ellipsoid", "box", "capsule".
const char* coreName(CoreShape core);

// The scene as JSON text (every field spelled out), readable by parseSceneText.
std::string sceneToJsonText(const std::vector<Primitive>& primitives, std::optional<double> voxelSize);

// Applies "N.field=value" to the scene's JSON (value: JSON, or numbers separated by commas, or a
// bare word) and validates the result; throws Error naming `assignment`.
std::string applySceneAssignment(const std::string& sceneJson, const std::string& assignment, const std::string& source);

} // namespace vdbsurf
