// The paper's loop (a)–(g). A polygon's facing is judged by the normals of its n corners (each
// from the corner and its two neighbours), so an n-gon can be front- and back-facing at once;
// a silhouette vertex ends an edge between a front-facing and a back-facing face, or a boundary
// edge (an open mesh's border is a contour too); a silhouette face holds a silhouette vertex.
#include "vdbsurf/subdiv/view_refine.h"

#include "vdbsurf/core/cancel.h"
#include "vdbsurf/core/error.h"
#include "vdbsurf/core/progress.h"
#include "vdbsurf/subdiv/sqrt2_subdivision.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>

namespace vdbsurf {

namespace {

constexpr std::uint32_t kFront = 1, kSilhouette = 2;

struct FaceView {
    bool inView = false, front = false, back = false;
    double pixels = 0; // diagonal of the projection's bounding box; infinite when behind the eye
};

FaceView classify(const std::vector<Vec3d>& corners, const CameraProjection& cam) {
    FaceView out;
    const std::size_t n = corners.size();
    // Outside when all corners lie beyond one plane of the view pyramid.
    bool allBehind = true, allLeft = true, allRight = true, allBelow = true, allAbove = true;
    double minX = std::numeric_limits<double>::max(), maxX = -minX, minY = minX, maxY = -minX;
    bool projectable = true;
    for (std::size_t k = 0; k < n; ++k) {
        const Vec3d c = cam.toCamera(corners[k]);
        allBehind &= c.z <= 0;
        allLeft &= c.x < -c.z * cam.tanHalfX();
        allRight &= c.x > c.z * cam.tanHalfX();
        allBelow &= c.y < -c.z * cam.tanHalfY();
        allAbove &= c.y > c.z * cam.tanHalfY();
        if (c.z <= 0) projectable = false;
        else {
            minX = std::min(minX, cam.pixelX(c));
            maxX = std::max(maxX, cam.pixelX(c));
            minY = std::min(minY, cam.pixelY(c));
            maxY = std::max(maxY, cam.pixelY(c));
        }
        const Vec3d& p = corners[k];
        const Vec3d normal = cross(corners[(k + 1) % n] - p, corners[(k + n - 1) % n] - p);
        const double facing = dot(normal, cam.eye() - p);
        out.front |= facing > 0;
        out.back |= facing < 0;
    }
    out.inView = !(allBehind || allLeft || allRight || allBelow || allAbove);
    out.pixels = projectable ? std::hypot(maxX - minX, maxY - minY) : std::numeric_limits<double>::infinity();
    return out;
}

std::vector<FaceView> classifyAll(const Sqrt2Subdivider& s, const CameraProjection& cam) {
    std::vector<FaceView> views(s.faceCount());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, views.size(), 512), [&](const tbb::blocked_range<std::size_t>& r) {
        std::vector<Vec3d> corners;
        for (std::size_t f = r.begin(); f != r.end(); ++f) {
            s.faceCorners(f, corners);
            views[f] = classify(corners, cam);
        }
    });
    return views;
}

// Faces (in view) that hold a silhouette vertex.
std::vector<std::uint8_t> silhouetteFaces(const Sqrt2Subdivider& s, const std::vector<FaceView>& views) {
    std::vector<std::pair<std::int64_t, std::int64_t>> edgeFaces;
    std::vector<std::pair<std::uint32_t, std::uint32_t>> edgeVertices;
    s.edgeFaces(edgeFaces, edgeVertices);
    std::vector<std::uint8_t> silhouetteVertex(s.vertexCount(), 0);
    for (std::size_t e = 0; e < edgeFaces.size(); ++e) {
        const auto [a, b] = edgeFaces[e];
        bool contour;
        if (a < 0 || b < 0) contour = true;
        else {
            const FaceView& fa = views[std::size_t(a)];
            const FaceView& fb = views[std::size_t(b)];
            contour = (fa.front && fb.back) || (fa.back && fb.front);
        }
        if (contour) silhouetteVertex[edgeVertices[e].first] = silhouetteVertex[edgeVertices[e].second] = 1;
    }
    std::vector<std::uint8_t> out(s.faceCount(), 0);
    std::vector<std::uint32_t> vs;
    for (std::size_t f = 0; f < out.size(); ++f) {
        if (!views[f].inView) continue;
        s.faceVertices(f, vs);
        for (std::uint32_t v : vs)
            if (silhouetteVertex[v]) out[f] = 1;
    }
    return out;
}

} // namespace

Mesh subdivideForView(const Mesh& mesh, const ViewCamera& camera, const ViewRefineOptions& options, const std::string& inputName,
                      ViewRefineReport* report) {
    validateCamera(camera, inputName);
    if (options.frontDepth < 0 || options.silhouetteDepth < 0) throw Error(inputName, "refinement depths must not be negative");
    Sqrt2Subdivider s(mesh, inputName);
    const CameraProjection cam(camera);
    ViewRefineReport rep;
    rep.inputFaces = s.faceCount();
    rep.splitVertices = s.splitVertices();

    // (1a)–(c): the initial front and silhouette sets.
    std::vector<FaceView> views = classifyAll(s, cam);
    std::vector<std::uint8_t> silhouette = silhouetteFaces(s, views);
    std::vector<std::uint32_t> flags(s.faceCount(), 0);
    for (std::size_t f = 0; f < flags.size(); ++f) {
        if (!views[f].inView) {
            ++rep.outsideView;
            continue;
        }
        if (views[f].front) flags[f] |= kFront;
        if (silhouette[f]) flags[f] |= kSilhouette;
        rep.initialFront += (flags[f] & kFront) != 0;
        rep.initialSilhouette += (flags[f] & kSilhouette) != 0;
    }

    const int deepest = std::max(options.frontDepth, options.silhouetteDepth);
    Progress progress("view refinement", std::uint64_t(std::max(deepest, 0)), options.cancel);
    for (int i = 1; i <= deepest; ++i) {
        if (options.cancel) options.cancel->check();
        // (b), (c): faces that meet the criterion leave their set.
        std::vector<std::uint8_t> refine(flags.size(), 0);
        std::size_t count = 0;
        for (std::size_t f = 0; f < flags.size(); ++f) {
            const bool small = views[f].pixels < options.stopPixels;
            if (i > options.frontDepth || small) flags[f] &= ~kFront;
            if (i > options.silhouetteDepth || small) flags[f] &= ~kSilhouette;
            refine[f] = flags[f] != 0;
            count += refine[f];
        }
        if (count == 0) break; // (a)
        // (d): refine the union; children inherit their parents' set membership.
        s.setTags(flags, Sqrt2Subdivider::TagMerge::BitOr);
        s.step(refine);
        progress.advance();
        rep.refinedPerStep.push_back(count);
        // (e), (f): children stay in a set only while they still face the camera or hold the silhouette.
        flags = s.tags();
        views = classifyAll(s, cam);
        silhouette = silhouetteFaces(s, views);
        for (std::size_t f = 0; f < flags.size(); ++f) {
            if (!views[f].inView) flags[f] = 0;
            if (!views[f].front) flags[f] &= ~kFront;
            if (!silhouette[f]) flags[f] &= ~kSilhouette;
        }
    }
    Mesh out = s.mesh();
    rep.outputFaces = out.polygonCount();
    if (report) *report = rep;
    return out;
}

} // namespace vdbsurf
