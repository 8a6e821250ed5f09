#include "vdbsurf/vdb/vdb_file.h"

#include "vdbsurf/core/atomic_file.h"
#include "vdbsurf/core/error.h"
#include "vdbsurf/vdb/allocation_cap.h"
#include "vdbsurf/vdb/content_uuid.h"
#include "vdbsurf/vdb/vdb_layout.h"
#include "vdbsurf/vdb/vdb_tree_layout.h"

#include <openvdb/openvdb.h>

#include <filesystem>
#include <fstream>
#include <mutex>

namespace vdbsurf {

namespace fs = std::filesystem;

void initializeOpenVdb() {
    static std::once_flag once;
    std::call_once(once, [] { openvdb::initialize(); });
}

namespace {

std::string className(openvdb::GridClass c) {
    switch (c) {
    case openvdb::GRID_LEVEL_SET: return "level set";
    case openvdb::GRID_FOG_VOLUME: return "fog";
    case openvdb::GRID_STAGGERED: return "staggered";
    default: return "unknown";
    }
}

bool isScalarType(const openvdb::GridBase& g) {
    return g.isType<openvdb::FloatGrid>() || g.isType<openvdb::DoubleGrid>();
}

// Opens a file with checks that turn OpenVDB's generic failures into messages a user can act on.
class OpenedFile {
public:
    explicit OpenedFile(const std::string& path) : mPath(path), mFile(path) {
        initializeOpenVdb();
        std::error_code ec;
        if (!fs::exists(path, ec)) throw Error(path, "no such file");
        if (fs::is_directory(path, ec)) throw Error(path, "is a folder, not a .vdb file");
        std::ifstream probe(path, std::ios::binary);
        if (!probe) throw Error(path, "cannot be read (permission denied?)");
        char magic[8] = {};
        probe.read(magic, 8);
        // OpenVDB files start with the 32-bit magic number 0x56444220 ("VDB " read little-endian).
        if (probe.gcount() < 8 || !(magic[0] == 0x20 && magic[1] == 0x42 && magic[2] == 0x44 && magic[3] == 0x56))
            throw Error(path, "is not an OpenVDB file");
        mSize = std::size_t(fs::file_size(path, ec));
        mLayout = checkVdbLayout(path);
        try {
            AllocationCap cap(structureCap());
            mFile.open(/*delayLoad=*/false);
        } catch (const std::bad_alloc&) {
            throw Error(path, "is damaged or truncated (its header asks for more data than the file holds)");
        } catch (const std::exception& e) {
            throw Error(path, std::string("is damaged or truncated: ") + e.what());
        }
    }
    ~OpenedFile() {
        try { if (mFile.isOpen()) mFile.close(); } catch (...) {}
    }
    openvdb::io::File& file() { return mFile; }

    openvdb::GridPtrVecPtr metadata() {
        try {
            AllocationCap cap(structureCap());
            return mFile.readAllGridMetadata();
        } catch (const std::bad_alloc&) {
            throw Error(mPath, "is damaged or truncated (its metadata asks for more data than the file holds)");
        } catch (const std::exception& e) {
            throw Error(mPath, std::string("is damaged or truncated: ") + e.what());
        }
    }
    openvdb::GridBase::Ptr read(const std::string& name) {
        // OpenVDB finds a grid by its plain or its unique name.
        for (const VdbGridExtent& g : mLayout.grids)
            if (g.name == name || g.plainName() == name) checkGridTreeLayout(mPath, mLayout, g);
        try {
            // Leaf buffers and node tables are small; no single block of a grid can need more
            // than many times the file's size, even decompressed.
            AllocationCap cap(std::max<std::size_t>(mSize * 64, std::size_t(256) << 20));
            return mFile.readGrid(name);
        } catch (const std::bad_alloc&) {
            throw Error(mPath, "grid " + gridLabel(name) + " cannot be read: the file is damaged or truncated");
        } catch (const std::exception& e) {
            throw Error(mPath, "grid " + gridLabel(name) + " cannot be read (file damaged or truncated): " + e.what());
        }
    }

private:
    // Strings, metadata and descriptors are stored whole in the file: none can exceed it. The
    // floor leaves room for the reader's own buffers (a file stream's is 8 KiB, more than a
    // small file holds), far below what a garbage length asks for.
    std::size_t structureCap() const { return std::max<std::size_t>(mSize, std::size_t(16) << 20); }

    std::string mPath;
    VdbLayout mLayout;
    openvdb::io::File mFile;
    std::size_t mSize = 0;
};

std::string gridList(const openvdb::GridPtrVec& grids) {
    std::string s;
    for (const auto& g : grids) {
        if (!s.empty()) s += ", ";
        s += gridLabel(g->getName()) + " (" + g->valueType() + ")";
    }
    return s.empty() ? "none" : s;
}

template <typename T>
bool readMeta(const openvdb::GridBase& g, const char* key, T& out) {
    if (auto m = g.getMetadata<openvdb::TypedMetadata<T>>(key)) { out = m->value(); return true; }
    return false;
}

} // namespace

std::vector<GridSummary> summarizeVdbFile(const std::string& path, bool verify) {
    OpenedFile f(path);
    const auto grids = f.metadata();
    std::vector<GridSummary> out;
    for (const auto& meta : *grids) {
        GridSummary s;
        s.name = meta->getName();
        s.valueType = meta->valueType();
        s.gridClass = className(meta->getGridClass());
        const openvdb::Vec3d vs = meta->voxelSize();
        s.voxelSize = {vs.x(), vs.y(), vs.z()};
        s.frustum = !meta->transform().isLinear();
        s.scalar = isScalarType(*meta);
        readMeta(*meta, "vdbsurf_scene", s.scene);
        readMeta(*meta, "vdbsurf_surface_only", s.surfaceOnly);
        // Writers record voxel count and bounds as grid metadata; read the grid only when absent.
        openvdb::Int64 count = 0;
        openvdb::Vec3i bmin, bmax;
        openvdb::CoordBBox bbox;
        if (!verify && readMeta(*meta, openvdb::GridBase::META_FILE_VOXEL_COUNT, count) &&
            readMeta(*meta, openvdb::GridBase::META_FILE_BBOX_MIN, bmin) &&
            readMeta(*meta, openvdb::GridBase::META_FILE_BBOX_MAX, bmax)) {
            s.activeVoxels = std::uint64_t(count);
            bbox = openvdb::CoordBBox(openvdb::Coord(bmin), openvdb::Coord(bmax));
        } else {
            const auto grid = f.read(s.name);
            s.activeVoxels = grid->activeVoxelCount();
            bbox = grid->evalActiveVoxelBoundingBox();
        }
        s.empty = s.activeVoxels == 0 || bbox.empty();
        if (!s.empty) {
            // World bounds of the voxels' extent (voxel centres +- half a voxel), as vdb_tool prints.
            const openvdb::BBoxd ib(bbox.min().asVec3d() - 0.5, bbox.max().asVec3d() + 0.5);
            const openvdb::BBoxd wb = meta->transform().indexToWorld(ib);
            s.worldBounds = {{wb.min().x(), wb.min().y(), wb.min().z()}, {wb.max().x(), wb.max().y(), wb.max().z()}};
        }
        out.push_back(s);
    }
    return out;
}

LoadedGrid readScalarGrid(const std::string& path, const std::string& name) {
    std::string note;
    OpenedFile f(path);
    const auto grids = f.metadata();
    if (grids->empty()) throw Error(path, "holds no grids");
    std::string chosen; // "" names an unnamed grid
    bool found = false;
    if (!name.empty()) {
        for (const auto& g : *grids)
            if (g->getName() == name) found = true;
        chosen = name;
        if (!found) throw Error(path, "no grid named '" + name + "'; grids: " + gridList(*grids));
        for (const auto& g : *grids) {
            if (g->getName() == name && !isScalarType(*g))
                throw Error(path, "grid '" + name + "' holds " + g->valueType() +
                                      " values; vdbsurf meshes float or double grids. Grids: " + gridList(*grids));
        }
        note = "using grid " + gridLabel(chosen);
    } else {
        int scalars = 0;
        for (const auto& g : *grids) {
            if (!isScalarType(*g)) continue;
            if (!found) chosen = g->getName();
            found = true;
            ++scalars;
        }
        if (!found) throw Error(path, "holds no float or double grid to mesh; grids: " + gridList(*grids));
        note = "using grid " + gridLabel(chosen) +
               (scalars == 1 ? " (the only scalar grid)" : " (the first of " + std::to_string(scalars) + " scalar grids; choose with --grid)");
    }
    return {f.read(chosen), chosen, note, chosen.empty() ? path : path + ":" + chosen};
}

std::string gridLabel(const std::string& name) { return name.empty() ? "(unnamed)" : "'" + name + "'"; }

void writeVdbFile(const std::string& path, const std::vector<GridBasePtr>& grids) {
    initializeOpenVdb();
    AtomicFile out(path);
    try {
        openvdb::io::File file(out.tempPath());
        openvdb::MetaMap meta;
        meta.insertMeta("creator", openvdb::StringMetadata(std::string("vdbsurf ") + VDBSURF_VERSION));
        openvdb::GridCPtrVec vec(grids.begin(), grids.end());
        file.write(vec, meta);
        file.close();
    } catch (const std::exception& e) {
        throw Error(path, std::string("cannot write: ") + e.what());
    }
    try {
        stampContentUuid(out.tempPath()); // the same grids give the same file (content_uuid.h)
    } catch (const Error& e) { // it names the temporary file; the user knows the output's name
        throw Error(path, "cannot write: the temporary file " + std::string(e.what()));
    }
    out.commit();
}

} // namespace vdbsurf
