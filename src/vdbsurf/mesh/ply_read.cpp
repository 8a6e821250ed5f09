// PLY reader: ascii, binary little- and big-endian; "vertex" x y z of any numeric type and
// "face" vertex_indices (or vertex_index) lists; other elements and properties are skipped.
// Hand-written for the same reason as the OBJ reader: every polygon kept, errors named.
#include "vdbsurf/core/error.h"
#include "vdbsurf/core/read_file.h"
#include "vdbsurf/mesh/mesh_io.h"

#include <charconv>
#include <cmath>
#include <cstring>
#include <sstream>

namespace vdbsurf {

namespace {

enum class Encoding { Ascii, Little, Big };

struct Property {
    std::string name;
    std::string type;      // scalar type, or the item type of a list
    std::string countType; // empty unless a list
};

struct Element {
    std::string name;
    std::size_t count = 0;
    std::vector<Property> properties;
};

std::size_t typeSize(const std::string& t) {
    if (t == "char" || t == "uchar" || t == "int8" || t == "uint8") return 1;
    if (t == "short" || t == "ushort" || t == "int16" || t == "uint16") return 2;
    if (t == "int" || t == "uint" || t == "int32" || t == "uint32" || t == "float" || t == "float32") return 4;
    if (t == "double" || t == "float64") return 8;
    return 0;
}

class Body {
public:
    Body(const std::string& path, const std::string& data, std::size_t start, Encoding enc)
        : mPath(path), mData(data), mPos(start), mEnc(enc) {}

    double read(const std::string& type) {
        if (mEnc == Encoding::Ascii) return readAscii();
        const std::size_t n = typeSize(type);
        if (mPos + n > mData.size()) throw Error(mPath, "file ends before the data its header declares");
        unsigned char b[8];
        std::memcpy(b, mData.data() + mPos, n);
        mPos += n;
        if (mEnc == Encoding::Big)
            for (std::size_t i = 0; i < n / 2; ++i) std::swap(b[i], b[n - 1 - i]);
        auto as = [&](auto v) {
            std::memcpy(&v, b, sizeof v);
            return double(v);
        };
        if (type == "char" || type == "int8") return as(std::int8_t());
        if (type == "uchar" || type == "uint8") return as(std::uint8_t());
        if (type == "short" || type == "int16") return as(std::int16_t());
        if (type == "ushort" || type == "uint16") return as(std::uint16_t());
        if (type == "int" || type == "int32") return as(std::int32_t());
        if (type == "uint" || type == "uint32") return as(std::uint32_t());
        if (type == "float" || type == "float32") return as(float());
        return as(double());
    }

    std::size_t remaining() const { return mData.size() - mPos; }

private:
    double readAscii() {
        while (mPos < mData.size() && std::isspace((unsigned char)mData[mPos])) ++mPos;
        const char* b = mData.data() + mPos;
        const char* e = mData.data() + mData.size();
        double v = 0;
        const auto r = std::from_chars(b, e, v);
        if (r.ec != std::errc()) {
            if (b == e) throw Error(mPath, "file ends before the data its header declares");
            throw Error(mPath, "a value in the body is not a number");
        }
        mPos += std::size_t(r.ptr - b);
        return v;
    }

    const std::string& mPath;
    const std::string& mData;
    std::size_t mPos;
    Encoding mEnc;
};

} // namespace

Mesh readPly(const std::string& path) {
    const std::string data = readWholeFile(path);
    if (data.compare(0, 3, "ply") != 0) throw Error(path, "not a PLY file (no 'ply' magic)");
    const std::size_t headerEnd = data.find("end_header");
    if (headerEnd == std::string::npos) throw Error(path, "PLY header has no end_header");
    std::size_t bodyStart = data.find('\n', headerEnd);
    if (bodyStart == std::string::npos) throw Error(path, "PLY file ends after its header");
    ++bodyStart;

    Encoding enc = Encoding::Ascii;
    bool haveFormat = false;
    std::vector<Element> elements;
    std::istringstream header(data.substr(0, headerEnd));
    std::string line;
    while (std::getline(header, line)) {
        std::istringstream ls(line);
        std::string word;
        ls >> word;
        if (word == "format") {
            std::string f;
            ls >> f;
            if (f == "ascii") enc = Encoding::Ascii;
            else if (f == "binary_little_endian") enc = Encoding::Little;
            else if (f == "binary_big_endian") enc = Encoding::Big;
            else throw Error(path, "unknown PLY format '" + f + "'");
            haveFormat = true;
        } else if (word == "element") {
            Element e;
            long long count = -1;
            ls >> e.name >> count;
            if (!ls || count < 0) throw Error(path, "malformed PLY element line: " + line);
            e.count = std::size_t(count);
            elements.push_back(e);
        } else if (word == "property") {
            if (elements.empty()) throw Error(path, "PLY property before any element");
            Property p;
            std::string t;
            ls >> t;
            if (t == "list") ls >> p.countType >> p.type >> p.name;
            else {
                p.type = t;
                ls >> p.name;
            }
            if (!ls || typeSize(p.type) == 0 || (!p.countType.empty() && typeSize(p.countType) == 0))
                throw Error(path, "malformed PLY property line: " + line);
            elements.back().properties.push_back(p);
        }
    }
    if (!haveFormat) throw Error(path, "PLY header has no format line");

    Mesh mesh;
    Body body(path, data, bodyStart, enc);
    std::vector<std::uint32_t> face;
    bool sawVertices = false;
    for (const Element& e : elements) {
        const bool isVertex = e.name == "vertex";
        const bool isFace = e.name == "face";
        int axis[3] = {-1, -1, -1};
        int indexList = -1;
        for (std::size_t i = 0; i < e.properties.size(); ++i) {
            const Property& p = e.properties[i];
            if (isVertex && p.countType.empty()) {
                if (p.name == "x") axis[0] = int(i);
                if (p.name == "y") axis[1] = int(i);
                if (p.name == "z") axis[2] = int(i);
            }
            if (isFace && !p.countType.empty() && (p.name == "vertex_indices" || p.name == "vertex_index")) indexList = int(i);
        }
        if (isVertex && (axis[0] < 0 || axis[1] < 0 || axis[2] < 0)) throw Error(path, "PLY vertex element lacks x, y or z");
        if (isFace && indexList < 0) throw Error(path, "PLY face element lacks a vertex_indices list");
        // Every row takes some bytes (binary: its scalars and list lengths; ascii: a character and
        // a separator a value), so a count the rest of the file cannot hold is refused before
        // anything is sized by it: a damaged header must not ask for gigabytes.
        std::size_t rowBytes = 0;
        for (const Property& p : e.properties) rowBytes += enc == Encoding::Ascii ? 2 : typeSize(p.countType.empty() ? p.type : p.countType);
        if (rowBytes > 0 && e.count > (body.remaining() + 1) / rowBytes)
            throw Error(path, "file ends before the data its header declares (" + std::to_string(e.count) + " " + e.name + " rows)");
        if (isVertex) {
            sawVertices = true;
            mesh.points.reserve(e.count);
        }
        if (rowBytes == 0) continue; // an element without properties holds nothing to read
        for (std::size_t row = 0; row < e.count; ++row) {
            Vec3f v;
            face.clear();
            for (std::size_t i = 0; i < e.properties.size(); ++i) {
                const Property& p = e.properties[i];
                if (p.countType.empty()) {
                    const double x = body.read(p.type);
                    for (int a = 0; a < 3; ++a)
                        if (isVertex && int(i) == axis[a]) {
                            if (!std::isfinite(x)) throw Error(path, "vertex " + std::to_string(row) + " has a coordinate that is not finite");
                            v[std::size_t(a)] = float(x);
                        }
                    continue;
                }
                const double n = body.read(p.countType);
                if (n < 0 || n != std::floor(n)) throw Error(path, "a PLY list has a bad length");
                for (std::size_t k = 0; k < std::size_t(n); ++k) {
                    const double x = body.read(p.type);
                    if (int(i) != indexList) continue;
                    if (!sawVertices || x < 0 || x >= double(mesh.points.size()) || x != std::floor(x))
                        throw Error(path, "face " + std::to_string(row) + " has vertex index " + std::to_string((long long)x) +
                                              " out of range (" + std::to_string(mesh.points.size()) + " vertices)");
                    face.push_back(std::uint32_t(x));
                }
            }
            if (isVertex) mesh.points.push_back(v);
            if (isFace) {
                if (face.size() < 3) throw Error(path, "face " + std::to_string(row) + " has fewer than three vertices");
                mesh.addPolygon(face.data(), face.size());
            }
        }
    }
    if (mesh.empty()) throw Error(path, "holds no polygons");
    return mesh;
}

} // namespace vdbsurf
