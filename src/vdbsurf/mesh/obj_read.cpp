// Wavefront OBJ reader: "v" positions and "f" polygons (v, v/vt, v/vt/vn, v//vn; negative
// indices count back from the last vertex); a backslash ending a line joins the next to it (the
// format's continuation, which some exporters use for long faces). Everything else (vt, vn, g,
// o, s, usemtl, l, ...) is skipped. Written here rather than taken from OpenMesh's reader
// because that one drops polygons it cannot add to a halfedge mesh with only a warning; we want
// every polygon, and errors that name the line.
#include "vdbsurf/core/error.h"
#include "vdbsurf/core/read_file.h"
#include "vdbsurf/mesh/mesh_io.h"

#include <charconv>
#include <cmath>

namespace vdbsurf {

namespace {

bool isSpace(char c) { return c == ' ' || c == '\t' || c == '\r'; }

struct LineReader {
    const char* p;
    const char* end;
    void skipSpace() {
        while (p < end && isSpace(*p)) ++p;
    }
    bool atEnd() {
        skipSpace();
        return p >= end || *p == '#';
    }
    const char* tokenEnd() const {
        const char* q = p;
        while (q < end && !isSpace(*q)) ++q;
        return q;
    }
};

} // namespace

Mesh readObj(const std::string& path) {
    const std::string text = readWholeFile(path);
    Mesh mesh;
    std::vector<std::uint32_t> face;
    std::size_t lineNo = 0, startLine = 0; // the line read last, the one its statement starts on
    const char* p = text.data();
    const char* const textEnd = p + text.size();
    auto fail = [&](const std::string& what) { throw Error(path, "line " + std::to_string(startLine) + ": " + what); };
    // Where a line [b, e) ends in a backslash (before a '\r' or blanks), the backslash: the next
    // line continues it.
    auto continued = [](const char* b, const char* e) -> const char* {
        while (e > b && (e[-1] == '\r' || e[-1] == ' ' || e[-1] == '\t')) --e;
        return e > b && e[-1] == '\\' ? e - 1 : nullptr;
    };
    std::string joined; // a line continued by backslashes, put together
    while (p < textEnd) {
        startLine = ++lineNo;
        const char* eol = p;
        while (eol < textEnd && *eol != '\n') ++eol;
        LineReader line{p, eol};
        line.skipSpace();
        // (Not a comment's: one ending in a Windows folder would swallow the next statement.)
        const char* cut = line.p < eol && *line.p == '#' ? nullptr : continued(p, eol);
        if (cut) {
            joined.assign(p, cut);
            while (true) {
                p = eol + 1;
                if (p >= textEnd) break;
                ++lineNo;
                eol = p;
                while (eol < textEnd && *eol != '\n') ++eol;
                const char* more = continued(p, eol);
                joined += ' ';
                joined.append(p, more ? more : eol);
                if (!more) break;
            }
            line = LineReader{joined.data(), joined.data() + joined.size()};
        }
        p = eol + 1;
        line.skipSpace();
        const char* tagEnd = line.tokenEnd();
        const std::string_view tag(line.p, std::size_t(tagEnd - line.p));
        line.p = tagEnd;
        if (tag == "v") {
            Vec3f v;
            for (int a = 0; a < 3; ++a) {
                line.skipSpace();
                double x = 0;
                const char* te = line.tokenEnd();
                const auto r = std::from_chars(line.p, te, x);
                if (r.ec != std::errc() || r.ptr != te) fail("a vertex needs three numbers");
                if (!std::isfinite(x)) fail("a vertex coordinate is not finite");
                v[std::size_t(a)] = float(x);
                line.p = te;
            }
            mesh.points.push_back(v);
        } else if (tag == "f") {
            face.clear();
            while (!line.atEnd()) {
                const char* te = line.tokenEnd();
                long long index = 0;
                const auto r = std::from_chars(line.p, te, index);
                if (r.ec != std::errc() || (r.ptr != te && *r.ptr != '/')) fail("a face corner is not an index");
                const long long count = (long long)mesh.points.size();
                const long long resolved = index < 0 ? count + index : index - 1;
                if (index == 0 || resolved < 0 || resolved >= count)
                    fail("face index " + std::to_string(index) + " is out of range (" + std::to_string(count) + " vertices so far)");
                face.push_back(std::uint32_t(resolved));
                line.p = te;
            }
            if (face.size() < 3) fail("a face needs at least three vertices");
            mesh.addPolygon(face.data(), face.size());
        }
    }
    if (mesh.empty()) throw Error(path, "holds no polygons");
    return mesh;
}

} // namespace vdbsurf
