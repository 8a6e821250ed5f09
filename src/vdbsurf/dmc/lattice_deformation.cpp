#include "vdbsurf/dmc/lattice_deformation.h"

#include "vdbsurf/lattice/lattice.h"
#include "vdbsurf/vdb/vdb_file.h"
#include "vdbsurf/vdb/voxel_transform.h"


namespace vdbsurf {

namespace {
// (Straight into the lattice's tree: a tree of the cells to add, united afterwards, allocated a
// full set of internal nodes for a handful of cells.)
void activateAround(Lattice& lattice, openvdb::tree::ValueAccessor<CellTree>& cells, const openvdb::Coord& n) {
    for (int d = 0; d < 8; ++d) {
        const openvdb::Coord c = n.offsetBy(-(d & 1), -((d >> 1) & 1), -((d >> 2) & 1));
        if (lattice.cellRange.isInside(c)) cells.setValueOn(c);
    }
}
} // namespace

void LatticeDeformation::release() {
    // (A tree another owner still holds, say --lattice-out's, is left to it.)
    auto drop = [](auto& tree) {
        if (tree.use_count() == 1) clearTree(*tree);
        tree.reset();
    };
    drop(offsets);
    drop(onSurface);
    drop(insideOnSurface);
    *this = LatticeDeformation();
}

void activateCellsAroundMovedNodes(Lattice& lattice, const LatticeDeformation& deformation) {
    openvdb::tree::ValueAccessor<CellTree> cells(*lattice.cells);
    // Nodes placed on features have offsets too.
    for (auto it = deformation.offsets->cbeginValueOn(); it; ++it) activateAround(lattice, cells, it.getCoord());
}

void activateCellsAround(Lattice& lattice, const std::vector<Vec3i>& nodes) {
    openvdb::tree::ValueAccessor<CellTree> cells(*lattice.cells);
    for (const Vec3i& n : nodes) activateAround(lattice, cells, openvdb::Coord(n.x, n.y, n.z));
}

std::vector<GridBasePtr> latticeGrids(const Lattice& lattice, const LatticeDeformation& deformation,
                                      const std::map<std::string, std::string>& metadata, const OwnFrame* own, const std::string& what) {
    initializeOpenVdb();
    const auto xform = latticeTransform(lattice.frame, own, what);

    // Nodes of active cells: the cells dilated by one towards +x, +y, +z.
    const openvdb::MaskTree::Ptr cellMask = toStandardMaskTree(*lattice.cells);
    openvdb::MaskTree nodes(*cellMask);
    {
        openvdb::MaskTree shifted(false);
        for (auto it = lattice.cells->cbeginValueOn(); it; ++it)
            for (int d = 1; d < 8; ++d) shifted.setValueOn(it.getCoord().offsetBy(d & 1, (d >> 1) & 1, (d >> 2) & 1));
        nodes.topologyUnion(shifted);
    }
    auto offsets = openvdb::Vec3SGrid::create(openvdb::Vec3f(0.0f));
    offsets->tree().topologyUnion(nodes);
    auto acc = offsets->getAccessor();
    for (auto it = deformation.offsets->cbeginValueOn(); it; ++it) {
        if (!own) {
            acc.setValue(it.getCoord(), *it);
            continue;
        }
        const openvdb::Coord& c = it.getCoord();
        const Vec3d w = own->offsetToWorld(lattice.frame.nodeWorld(Vec3i(c.x(), c.y(), c.z())), Vec3d(it->x(), it->y(), it->z()));
        acc.setValue(it.getCoord(), openvdb::Vec3f(float(w.x), float(w.y), float(w.z)));
    }
    offsets->setName("offsets");
    offsets->setVectorType(openvdb::VEC_CONTRAVARIANT_ABSOLUTE);
    offsets->setTransform(xform);
    auto cells = openvdb::MaskGrid::create(false);
    cells->setTree(cellMask);
    cells->setName("cells");
    // A cell's voxel sits at its min-corner node: the same index space as the nodes.
    cells->setTransform(xform->copy());
    auto surface = openvdb::MaskGrid::create(false);
    {
        auto on = surface->getAccessor();
        for (auto it = deformation.onSurface->cbeginValueOn(); it; ++it) on.setValueOn(it.getCoord());
    }
    surface->setName("on_surface");
    surface->setTransform(xform->copy());
    for (openvdb::GridBase* g : std::initializer_list<openvdb::GridBase*>{offsets.get(), cells.get(), surface.get()})
        for (const auto& [k, v] : metadata) g->insertMeta(k, openvdb::StringMetadata(v));
    return {offsets, cells, surface};
}

void writeLatticeVdb(const std::string& path, const Lattice& lattice, const LatticeDeformation& deformation,
                     const std::map<std::string, std::string>& metadata, const OwnFrame* own) {
    writeVdbFile(path, latticeGrids(lattice, deformation, metadata, own, path));
}

} // namespace vdbsurf
