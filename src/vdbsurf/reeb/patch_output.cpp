#include "vdbsurf/reeb/patch_output.h"
#include "vdbsurf/core/atomic_file.h"
#include "vdbsurf/core/buffered_file.h"
#include "vdbsurf/core/cancel.h"
#include "vdbsurf/mesh/mesh_distance.h"
#include "vdbsurf/reeb/row_zip.h"

#include <nlohmann/json.hpp>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <map>

namespace vdbsurf::reeb {

namespace {

int spans(const std::vector<double>& knots) {
    int n = 0;
    for (std::size_t i = 1; i < knots.size(); ++i) n += knots[i] > knots[i - 1];
    return n;
}

} // namespace

Mesh tessellatePatches(const ReebGraph& g, const PatchSet& set, int density) {
    std::vector<Vec3d> pts;
    std::vector<std::uint32_t> tris;
    // Shared vertices: saddles and poles per node, samples per lobe (uniform, plus every seam).
    std::vector<std::uint32_t> nodeVertex(g.nodes.size());
    for (std::size_t n = 0; n < g.nodes.size(); ++n) {
        nodeVertex[n] = std::uint32_t(pts.size());
        pts.push_back(g.nodes[n].position);
    }
    std::vector<std::map<double, std::uint32_t>> lobeSamples(g.lobes.size());
    for (std::size_t li = 0; li < g.lobes.size(); ++li) {
        const int n = std::max(4, density * spans(set.lobeCurves[li].knots));
        for (int k = 1; k < n; ++k) lobeSamples[li][double(k) / n] = 0;
    }
    for (const UnitPatch& p : set.patches)
        for (const BoundaryPiece& b : p.boundary)
            for (double t : {b.t0, b.t1})
                if (t > 0 && t < 1) lobeSamples[b.lobe][t] = 0;
    for (std::size_t li = 0; li < g.lobes.size(); ++li)
        for (auto& [t, id] : lobeSamples[li]) {
            id = std::uint32_t(pts.size());
            pts.push_back(set.lobeCurves[li].eval(t));
        }
    for (std::size_t ui = 0; ui < set.patches.size(); ++ui) {
        const UnitPatch& p = set.patches[ui];
        const Unit& unit = g.units[ui];
        auto endRow = [&](bool top) {
            std::vector<RowVertex> row;
            if (top ? p.topPole : p.bottomPole) {
                const std::uint32_t v = nodeVertex[top ? unit.upper : unit.lower];
                return std::vector<RowVertex>{{v, 0.0}, {v, 1.0}};
            }
            const std::uint32_t saddle = nodeVertex[top ? unit.upper : unit.lower];
            for (const BoundaryPiece& b : p.boundary) {
                if (b.top != top) continue;
                auto vertexAt = [&](double t) { return t <= 0 || t >= 1 ? saddle : lobeSamples[b.lobe].at(t); };
                auto uOf = [&](double t) { return b.u0 + (t - b.t0) / (b.t1 - b.t0) * (b.u1 - b.u0); };
                if (row.empty()) row.push_back({vertexAt(b.t0), b.u0});
                const auto& samples = lobeSamples[b.lobe];
                for (auto it = samples.upper_bound(b.t0); it != samples.end() && it->first < b.t1; ++it)
                    row.push_back({it->second, uOf(it->first)});
                row.push_back({vertexAt(b.t1), b.u1});
            }
            return row;
        };
        const int nu = std::clamp(density * spans(p.surface.knotsU), 8, 1024);
        const int nv = std::clamp(density * spans(p.surface.knotsV), 2, 1024);
        std::vector<RowVertex> below = endRow(false);
        for (int j = 1; j <= nv; ++j) {
            std::vector<RowVertex> row;
            if (j == nv) row = endRow(true);
            else {
                const double v = double(j) / nv;
                const std::uint32_t first = std::uint32_t(pts.size());
                for (int i = 0; i < nu; ++i) {
                    row.push_back({std::uint32_t(pts.size()), double(i) / nu});
                    pts.push_back(p.surface.eval(double(i) / nu, v));
                }
                row.push_back({first, 1.0});
            }
            zipRows(below, row, tris);
            below = std::move(row);
        }
    }
    Mesh mesh;
    mesh.points.reserve(pts.size());
    for (const Vec3d& q : pts) mesh.points.push_back(Vec3f(q));
    mesh.indices = std::move(tris);
    mesh.offsets.resize(mesh.indices.size() / 3 + 1);
    for (std::size_t t = 0; t < mesh.offsets.size(); ++t) mesh.offsets[t] = std::uint32_t(3 * t);
    // Rows run along the contours' orientation; turn the triangles outwards if that made them face in.
    if (enclosedVolume(mesh) < 0)
        for (std::size_t t = 0; t + 1 < mesh.offsets.size(); ++t) std::swap(mesh.indices[3 * t + 1], mesh.indices[3 * t + 2]);
    return mesh;
}

FitError fitError(const ClosedSurface& s, const Mesh& tessellation, const CancelToken* cancel) {
    FitError e;
    e.meanEdgeLength = s.meanEdgeLength();
    if (!(e.meanEdgeLength > 0)) return e;
    const Box3 box = tessellation.bounds();
    const double farthest = std::max(length(box.extent()), e.meanEdgeLength);
    const MeshDistance distance(tessellation, 4 * e.meanEdgeLength);
    std::vector<double> d(s.points.size());
    // Near points answer within a few cells; the rare far one widens its search.
    tbb::parallel_for(std::size_t(0), s.points.size(), [&](std::size_t v) {
        if (cancel) cancel->check();
        for (double radius = 2 * e.meanEdgeLength;; radius *= 4) {
            d[v] = distance.distance(s.points[v], std::min(radius, farthest));
            if (d[v] < radius || radius >= farthest) break;
        }
    });
    double sum = 0;
    for (double x : d) {
        sum += x * x;
        e.max = std::max(e.max, x);
    }
    e.rms = std::sqrt(sum / double(std::max<std::size_t>(1, d.size()))) / e.meanEdgeLength;
    e.max /= e.meanEdgeLength;
    return e;
}

namespace {

void putNumber(std::string& s, double v) {
    char buf[32];
    s.append(buf, std::to_chars(buf, buf + sizeof buf, v).ptr);
}

} // namespace

void writePatchesObj(const std::string& path, const PatchSet& set, const std::vector<std::string>& comments) {
    AtomicFile target(path);
    {
        BufferedFile out(target);
        for (const std::string& c : comments) out.put("# " + c + "\n");
        std::size_t base = 1;
        for (std::size_t ui = 0; ui < set.patches.size(); ++ui) {
            const BSplinePatch& S = set.patches[ui].surface;
            std::string s;
            for (const Vec3d& c : S.ctrl) {
                s += "v";
                for (int a = 0; a < 3; ++a) {
                    s += ' ';
                    putNumber(s, c[std::size_t(a)]);
                }
                s += '\n';
            }
            s += "g unit" + std::to_string(ui) + "\ncstype bspline\ndeg 3 3\nsurf 0 1 0 1";
            for (std::size_t k = 0; k < S.ctrl.size(); ++k) s += " " + std::to_string(base + k);
            s += "\nparm u";
            for (double k : S.knotsU) {
                s += ' ';
                putNumber(s, k);
            }
            s += "\nparm v";
            for (double k : S.knotsV) {
                s += ' ';
                putNumber(s, k);
            }
            s += "\nend\n";
            base += S.ctrl.size();
            out.put(s);
        }
        out.close();
    }
    target.commit();
}

void writeReebJson(const std::string& path, const ReebGraph& g, const ClosedSurface& surface) {
    nlohmann::json j;
    j["axis"] = {g.axis.x, g.axis.y, g.axis.z};
    j["euler_characteristic"] = g.eulerCharacteristic;
    j["components"] = g.components;
    j["loops"] = g.loops();
    j["minima"] = g.minima;
    j["maxima"] = g.maxima;
    j["saddles"] = g.saddles;
    j["simplified"] = {{"minima_removed", g.simplified.minimaRemoved}, {"maxima_removed", g.simplified.maximaRemoved}};
    nlohmann::json nodes = nlohmann::json::array();
    for (std::size_t i = 0; i < g.nodes.size(); ++i) {
        const ReebNode& n = g.nodes[i];
        nodes.push_back({{"id", i},
                         {"type", criticalTypeName(n.type)},
                         {"multiplicity", n.multiplicity},
                         {"height", n.height},
                         {"position", {n.position.x, n.position.y, n.position.z}},
                         {"vertex", surface.inputVertex[n.vertex]}});
    }
    j["nodes"] = std::move(nodes);
    nlohmann::json arcs = nlohmann::json::array();
    for (std::size_t i = 0; i < g.units.size(); ++i) {
        const Unit& u = g.units[i];
        arcs.push_back({{"id", i},
                        {"lower", u.lower},
                        {"upper", u.upper},
                        {"kind", u.bottomLobes.empty() || u.topLobes.empty() ? (u.bottomLobes.empty() && u.topLobes.empty() ? "sphere" : "disk") : "cylinder"},
                        {"area", u.area},
                        {"faces", u.inputPolygons}});
    }
    j["arcs"] = std::move(arcs);
    AtomicFile target(path);
    {
        BufferedFile out(target);
        out.put(j.dump() + "\n");
        out.close();
    }
    target.commit();
}

} // namespace vdbsurf::reeb
