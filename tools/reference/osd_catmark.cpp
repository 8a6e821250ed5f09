#include "osd_catmark.h"

#include <opensubdiv/far/primvarRefiner.h>
#include <opensubdiv/far/topologyDescriptor.h>

#include <memory>

namespace vdbsurf::reference {

namespace {

using namespace OpenSubdiv;

struct Vertex {
    double p[3];
    void Clear(void* = nullptr) { p[0] = p[1] = p[2] = 0; }
    void AddWithWeight(const Vertex& v, float w) {
        p[0] += w * v.p[0];
        p[1] += w * v.p[1];
        p[2] += w * v.p[2];
    }
};

} // namespace

CatmarkResult catmullClark(const Mesh& mesh, int levels) {
    std::vector<int> counts(mesh.polygonCount());
    for (std::size_t f = 0; f < counts.size(); ++f) counts[f] = int(mesh.polygonSize(f));
    std::vector<int> indices(mesh.indices.begin(), mesh.indices.end());
    Far::TopologyDescriptor desc;
    desc.numVertices = int(mesh.points.size());
    desc.numFaces = int(counts.size());
    desc.numVertsPerFace = counts.data();
    desc.vertIndicesPerFace = indices.data();

    Sdc::Options options;
    options.SetVtxBoundaryInterpolation(Sdc::Options::VTX_BOUNDARY_EDGE_ONLY);
    using Factory = Far::TopologyRefinerFactory<Far::TopologyDescriptor>;
    std::unique_ptr<Far::TopologyRefiner> refiner(
        Factory::Create(desc, Factory::Options(Sdc::SCHEME_CATMARK, options)));
    refiner->RefineUniform(Far::TopologyRefiner::UniformOptions(levels));

    std::vector<Vertex> verts(std::size_t(refiner->GetNumVerticesTotal()));
    for (std::size_t i = 0; i < mesh.points.size(); ++i) verts[i] = {{mesh.points[i].x, mesh.points[i].y, mesh.points[i].z}};
    Far::PrimvarRefiner primvar(*refiner);
    Vertex* src = verts.data();
    for (int level = 1; level <= levels; ++level) {
        Vertex* dst = src + refiner->GetLevel(level - 1).GetNumVertices();
        primvar.Interpolate(level, src, dst);
        src = dst;
    }

    CatmarkResult out;
    const Far::TopologyLevel& last = refiner->GetLevel(levels);
    out.positions.reserve(std::size_t(last.GetNumVertices()));
    for (int v = 0; v < last.GetNumVertices(); ++v) out.positions.emplace_back(src[v].p[0], src[v].p[1], src[v].p[2]);
    for (int f = 0; f < last.GetNumFaces(); ++f) {
        const Far::ConstIndexArray fv = last.GetFaceVertices(f);
        for (int k = 0; k < fv.size(); ++k) out.indices.push_back(std::uint32_t(fv[k]));
        out.offsets.push_back(std::uint32_t(out.indices.size()));
    }
    return out;
}

} // namespace vdbsurf::reference
