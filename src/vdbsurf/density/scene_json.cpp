#include "vdbsurf/density/scene_json.h"

#include "vdbsurf/core/error.h"
#include "vdbsurf/core/read_file.h"

#include <nlohmann/json.hpp>

#include <cmath>
#include <set>
#include <sstream>
#include <vector>

namespace vdbsurf {

namespace {

using json = nlohmann::json;

std::string shortDump(const json& j) {
    std::string s = j.dump();
    return s.size() > 60 ? s.substr(0, 57) + "..." : s;
}

struct Where {
    const std::string& source;
    std::string primitive; // "primitive 2 (\"box\")"
    Error error(const std::string& field, const std::string& what) const {
        return Error(source, primitive + ": '" + field + "' " + what);
    }
};

double number(const Where& w, const json& j, const std::string& field) {
    if (!j.is_number()) throw w.error(field, "must be a number, not " + shortDump(j));
    const double v = j.get<double>();
    if (!std::isfinite(v)) throw w.error(field, "must be finite");
    return v;
}

Vec3d triple(const Where& w, const json& j, const std::string& field) {
    if (!j.is_array() || j.size() != 3) throw w.error(field, "must be an array of 3 numbers, not " + shortDump(j));
    return {number(w, j[0], field), number(w, j[1], field), number(w, j[2], field)};
}

Primitive parsePrimitive(const json& j, std::size_t index, const std::string& source) {
    Where w{source, "primitive " + std::to_string(index)};
    if (!j.is_object()) throw Error(source, w.primitive + ": must be an object, not " + shortDump(j));
    if (!j.contains("core")) throw Error(source, w.primitive + ": 'core' is missing (\"ellipsoid\", \"box\" or \"capsule\")");
    const json& core = j["core"];
    if (!core.is_string() || (core != "ellipsoid" && core != "box" && core != "capsule"))
        throw w.error("core", "must be \"ellipsoid\", \"box\" or \"capsule\", not " + shortDump(core));
    Primitive p;
    p.core = core == "box" ? CoreShape::Box : core == "capsule" ? CoreShape::Capsule : CoreShape::Ellipsoid;
    w.primitive += " (" + core.get<std::string>() + ")";
    const bool capsule = p.core == CoreShape::Capsule;
    // A capsule's size is two numbers (its segment along the local x axis, and its radius), the
    // others' one a local axis.
    const std::vector<std::string> sizeFields =
        capsule ? std::vector<std::string>{"half_length", "radius"} : std::vector<std::string>{p.core == CoreShape::Box ? "half_extents" : "radii"};
    std::set<std::string> allowed = {"core", "center", "rotation", "falloff", "weight", "op", "name"};
    allowed.insert(sizeFields.begin(), sizeFields.end());
    for (auto it = j.begin(); it != j.end(); ++it)
        if (!allowed.count(it.key())) {
            std::string list;
            for (const auto& a : allowed) list += (list.empty() ? "" : ", ") + a;
            throw w.error(it.key(), "is not a field of a " + core.get<std::string>() + " primitive (fields: " + list + ")");
        }
    if (j.contains("name")) {
        if (!j["name"].is_string()) throw w.error("name", "must be a string");
        p.name = j["name"].get<std::string>();
        w.primitive = "primitive " + std::to_string(index) + " (\"" + p.name + "\")";
    }
    std::vector<std::string> required = {"center", "falloff"};
    required.insert(required.end(), sizeFields.begin(), sizeFields.end());
    for (const std::string& field : required)
        if (!j.contains(field)) throw w.error(field, "is missing");
    p.center = triple(w, j["center"], "center");
    if (capsule) {
        const double halfLength = number(w, j["half_length"], "half_length"), radius = number(w, j["radius"], "radius");
        if (!(halfLength >= 0))
            throw w.error("half_length", "must be 0 or more (half the length of the segment the capsule rounds), not " + shortDump(j["half_length"]));
        if (!(radius > 0)) throw w.error("radius", "must be positive, not " + shortDump(j["radius"]));
        p.size = Vec3d(halfLength, radius, radius);
    } else {
        const std::string& sizeField = sizeFields[0];
        p.size = triple(w, j[sizeField], sizeField);
        for (int i = 0; i < 3; ++i)
            if (!(p.size[i] > 0)) throw w.error(sizeField, "must be positive on every axis, not " + shortDump(j[sizeField]));
    }
    if (j.contains("rotation")) p.rotationDegrees = triple(w, j["rotation"], "rotation");
    p.falloff = number(w, j["falloff"], "falloff");
    if (!(p.falloff > 0)) throw w.error("falloff", "must be positive (the width of the influence beyond the core), not " + shortDump(j["falloff"]));
    if (j.contains("weight")) {
        p.weight = number(w, j["weight"], "weight");
        if (!(p.weight > 0) || !(p.weight <= kMaxWeight))
            throw w.error("weight", "must be positive and at most " + std::to_string(int(kMaxWeight)) +
                                        " (the surface is at 0.5 and sums clamp at 1), not " + shortDump(j["weight"]));
    }
    if (j.contains("op")) {
        const json& op = j["op"];
        if (!op.is_string() || (op != "add" && op != "subtract"))
            throw w.error("op", "must be \"add\" or \"subtract\", not " + shortDump(op));
        p.op = op == "add" ? DensityOp::Add : DensityOp::Subtract;
    }
    return p;
}

DensityScene parseSceneJson(const json& doc, const std::string& source) {
    if (!doc.is_object()) throw Error(source, "a scene must be a JSON object with \"primitives\"");
    for (auto it = doc.begin(); it != doc.end(); ++it)
        if (it.key() != "primitives" && it.key() != "voxel_size")
            throw Error(source, "'" + it.key() + "' is not a scene field (fields: primitives, voxel_size)");
    if (!doc.contains("primitives") || !doc["primitives"].is_array())
        throw Error(source, "'primitives' must be an array of primitives");
    std::vector<Primitive> prims;
    for (std::size_t i = 0; i < doc["primitives"].size(); ++i) prims.push_back(parsePrimitive(doc["primitives"][i], i, source));
    std::optional<double> voxel;
    if (doc.contains("voxel_size")) {
        const json& v = doc["voxel_size"];
        if (!v.is_number() || !(v.get<double>() > 0) || !std::isfinite(v.get<double>()))
            throw Error(source, "'voxel_size' must be a positive number, not " + shortDump(v));
        voxel = v.get<double>();
    }
    return DensityScene(std::move(prims), source, voxel);
}

json parseText(const std::string& text, const std::string& source) {
    try {
        return json::parse(text);
    } catch (const json::parse_error& e) {
        std::string what = e.what();
        const auto colon = what.find("parse error");
        throw Error(source, "is not valid JSON (" + (colon == std::string::npos ? what : what.substr(colon)) + ")");
    }
}

json primitiveJson(const Primitive& p) {
    json j{{"core", coreName(p.core)},
           {"center", {p.center.x, p.center.y, p.center.z}},
           {"rotation", {p.rotationDegrees.x, p.rotationDegrees.y, p.rotationDegrees.z}},
           {"falloff", p.falloff},
           {"weight", p.weight},
           {"op", p.op == DensityOp::Add ? "add" : "subtract"}};
    if (p.core == CoreShape::Capsule) {
        j["half_length"] = p.size.x;
        j["radius"] = p.size.y;
    } else {
        j[p.core == CoreShape::Box ? "half_extents" : "radii"] = {p.size.x, p.size.y, p.size.z};
    }
    if (!p.name.empty()) j["name"] = p.name;
    return j;
}

} // namespace

const char* coreName(CoreShape core) {
    switch (core) {
    case CoreShape::Ellipsoid: return "ellipsoid";
    case CoreShape::Box: return "box";
    case CoreShape::Capsule: return "capsule";
    }
    return "?";
}

DensityScene parseSceneText(const std::string& text, const std::string& source) {
    return parseSceneJson(parseText(text, source), source);
}

DensityScene readSceneFile(const std::string& path) {
    return parseSceneText(readWholeFile(path), path);
}

Primitive parsePrimitiveText(const std::string& text, std::size_t index, const std::string& source) {
    return parsePrimitive(parseText(text, source), index, source);
}

std::string sceneToJsonText(const std::vector<Primitive>& primitives, std::optional<double> voxelSize) {
    json doc;
    doc["primitives"] = json::array();
    for (const Primitive& p : primitives) doc["primitives"].push_back(primitiveJson(p));
    if (voxelSize) doc["voxel_size"] = *voxelSize;
    return doc.dump(2) + "\n";
}

std::string applySceneAssignment(const std::string& sceneJson, const std::string& assignment, const std::string& source) {
    const auto eq = assignment.find('=');
    const auto dot = assignment.find('.');
    if (eq == std::string::npos || dot == std::string::npos || dot > eq)
        throw Error(assignment, "expected N.field=value, e.g. 0.center=1,0,0");
    const std::string indexText = assignment.substr(0, dot), field = assignment.substr(dot + 1, eq - dot - 1),
                      valueText = assignment.substr(eq + 1);
    std::size_t used = 0;
    long index = -1;
    try {
        index = std::stol(indexText, &used);
    } catch (...) {
    }
    json doc = parseText(sceneJson, source);
    const std::size_t count = doc.contains("primitives") && doc["primitives"].is_array() ? doc["primitives"].size() : 0;
    if (used != indexText.size() || index < 0 || std::size_t(index) >= count)
        throw Error(assignment, "no primitive " + indexText + " (the scene has " + std::to_string(count) + ", numbered from 0)");
    json value;
    try {
        value = json::parse(valueText);
    } catch (const json::parse_error&) {
        // Numbers separated by commas become an array; anything else a string.
        json list = json::array();
        std::stringstream ss(valueText);
        std::string item;
        bool numbers = !valueText.empty();
        while (numbers && std::getline(ss, item, ',')) {
            try {
                list.push_back(json::parse(item));
                numbers = list.back().is_number();
            } catch (const json::parse_error&) {
                numbers = false;
            }
        }
        value = numbers ? list : json(valueText);
    }
    doc["primitives"][std::size_t(index)][field] = value;
    const std::string out = doc.dump(2) + "\n";
    try {
        parseSceneJson(doc, source);
    } catch (const Error& e) {
        throw Error(assignment, std::string(e.what()).substr(source.size() + 2));
    }
    return out;
}

} // namespace vdbsurf
