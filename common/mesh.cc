#include "common/mesh.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <sstream>

#include <Eigen/Geometry>  // Vector3f::cross is defined here, not in <Eigen/Core>

#include "common/file_util.h"

namespace holo {

void Mesh::Clear() {
  positions.clear();
  normals.clear();
  colors.clear();
  triangles.clear();
}

Status Mesh::Validate() const {
  const size_t n = positions.size();
  if (!normals.empty() && normals.size() != n)
    return DataLoss("mesh has " + std::to_string(normals.size()) + " normals for " + std::to_string(n) + " vertices");
  if (!colors.empty() && colors.size() != n)
    return DataLoss("mesh has " + std::to_string(colors.size()) + " colors for " + std::to_string(n) + " vertices");
  for (size_t i = 0; i < n; ++i)
    if (!positions[i].allFinite()) return DataLoss("vertex " + std::to_string(i) + " is not finite");
  for (size_t t = 0; t < triangles.size(); ++t)
    for (uint32_t idx : triangles[t])
      if (idx >= n)
        return DataLoss("triangle " + std::to_string(t) + " references vertex " + std::to_string(idx) + " of " +
                        std::to_string(n));
  return OkStatus();
}

void Mesh::ComputeNormals() {
  normals.assign(positions.size(), Eigen::Vector3f::Zero());
  for (const auto& t : triangles) {
    const Eigen::Vector3f n = (positions[t[1]] - positions[t[0]]).cross(positions[t[2]] - positions[t[0]]);
    for (uint32_t i : t) normals[i] += n;
  }
  for (auto& n : normals) {
    const float len = n.norm();
    n = len > 0 ? Eigen::Vector3f(n / len) : Eigen::Vector3f(0, 0, 1);
  }
}

double Mesh::SurfaceArea() const {
  double area = 0;
  for (const auto& t : triangles)
    area += 0.5 * (positions[t[1]] - positions[t[0]]).cross(positions[t[2]] - positions[t[0]]).norm();
  return area;
}

void Mesh::Append(const Mesh& other) {
  const uint32_t base = static_cast<uint32_t>(positions.size());
  const bool had_normals = !normals.empty() || positions.empty();
  const bool had_colors = !colors.empty() || positions.empty();
  positions.insert(positions.end(), other.positions.begin(), other.positions.end());
  if (had_normals && !other.normals.empty()) normals.insert(normals.end(), other.normals.begin(), other.normals.end());
  else normals.clear();
  if (had_colors && !other.colors.empty()) colors.insert(colors.end(), other.colors.begin(), other.colors.end());
  else colors.clear();
  for (auto t : other.triangles) triangles.push_back({t[0] + base, t[1] + base, t[2] + base});
}

// ---------------------------------------------------------------------------
// PLY

Status WritePly(const std::string& path, const Mesh& mesh) {
  HOLO_RETURN_IF_ERROR(mesh.Validate().WithContext(path));
  const bool has_n = !mesh.normals.empty(), has_c = !mesh.colors.empty();
  std::ostringstream h;
  h << "ply\nformat binary_little_endian 1.0\ncomment Holoport mesh\n";
  h << "element vertex " << mesh.positions.size() << "\n";
  h << "property float x\nproperty float y\nproperty float z\n";
  if (has_n) h << "property float nx\nproperty float ny\nproperty float nz\n";
  if (has_c) h << "property uchar red\nproperty uchar green\nproperty uchar blue\n";
  h << "element face " << mesh.triangles.size() << "\nproperty list uchar uint vertex_indices\nend_header\n";
  std::string out = h.str();
  const size_t vsize = 12 + (has_n ? 12 : 0) + (has_c ? 3 : 0);
  out.reserve(out.size() + vsize * mesh.positions.size() + 13 * mesh.triangles.size());
  auto put = [&out](const void* p, size_t n) { out.append(static_cast<const char*>(p), n); };
  for (size_t i = 0; i < mesh.positions.size(); ++i) {
    put(mesh.positions[i].data(), 12);
    if (has_n) put(mesh.normals[i].data(), 12);
    if (has_c) put(mesh.colors[i].data(), 3);
  }
  for (const auto& t : mesh.triangles) {
    const uint8_t three = 3;
    put(&three, 1);
    put(t.data(), 12);
  }
  return WriteStringToFile(path, out);
}

namespace {

enum class PlyType { kInt8, kUint8, kInt16, kUint16, kInt32, kUint32, kFloat32, kFloat64, kInvalid };

PlyType ParsePlyType(const std::string& s) {
  if (s == "char" || s == "int8") return PlyType::kInt8;
  if (s == "uchar" || s == "uint8") return PlyType::kUint8;
  if (s == "short" || s == "int16") return PlyType::kInt16;
  if (s == "ushort" || s == "uint16") return PlyType::kUint16;
  if (s == "int" || s == "int32") return PlyType::kInt32;
  if (s == "uint" || s == "uint32") return PlyType::kUint32;
  if (s == "float" || s == "float32") return PlyType::kFloat32;
  if (s == "double" || s == "float64") return PlyType::kFloat64;
  return PlyType::kInvalid;
}

size_t PlyTypeSize(PlyType t) {
  switch (t) {
    case PlyType::kInt8: case PlyType::kUint8: return 1;
    case PlyType::kInt16: case PlyType::kUint16: return 2;
    case PlyType::kInt32: case PlyType::kUint32: case PlyType::kFloat32: return 4;
    case PlyType::kFloat64: return 8;
    default: return 0;
  }
}

struct PlyProperty {
  std::string name;
  PlyType type = PlyType::kInvalid;
  bool is_list = false;
  PlyType count_type = PlyType::kInvalid;
};

struct PlyElement {
  std::string name;
  uint64_t count = 0;
  std::vector<PlyProperty> props;
};

// Reads one value of `type` from binary little-endian bytes or ASCII tokens.
class PlyValueReader {
 public:
  PlyValueReader(const std::string& data, size_t pos, bool ascii) : data_(data), pos_(pos), ascii_(ascii) {}

  bool Read(PlyType type, double* out) {
    if (ascii_) {
      while (pos_ < data_.size() && std::isspace(static_cast<unsigned char>(data_[pos_]))) ++pos_;
      if (pos_ >= data_.size()) return false;
      const char* begin = data_.c_str() + pos_;
      char* end = nullptr;
      const double v = std::strtod(begin, &end);
      if (end == begin) return false;
      pos_ += static_cast<size_t>(end - begin);
      *out = v;
      return true;
    }
    const size_t n = PlyTypeSize(type);
    if (n == 0 || data_.size() - pos_ < n) return false;
    const char* p = data_.data() + pos_;
    pos_ += n;
    switch (type) {
      case PlyType::kInt8: { int8_t v; std::memcpy(&v, p, 1); *out = v; break; }
      case PlyType::kUint8: { uint8_t v; std::memcpy(&v, p, 1); *out = v; break; }
      case PlyType::kInt16: { int16_t v; std::memcpy(&v, p, 2); *out = v; break; }
      case PlyType::kUint16: { uint16_t v; std::memcpy(&v, p, 2); *out = v; break; }
      case PlyType::kInt32: { int32_t v; std::memcpy(&v, p, 4); *out = v; break; }
      case PlyType::kUint32: { uint32_t v; std::memcpy(&v, p, 4); *out = v; break; }
      case PlyType::kFloat32: { float v; std::memcpy(&v, p, 4); *out = v; break; }
      case PlyType::kFloat64: { double v; std::memcpy(&v, p, 8); *out = v; break; }
      default: return false;
    }
    return true;
  }
  size_t remaining() const { return data_.size() - pos_; }

 private:
  const std::string& data_;
  size_t pos_;
  bool ascii_;
};

}  // namespace

StatusOr<Mesh> ReadPly(const std::string& path) {
  HOLO_ASSIGN_OR_RETURN(std::string data, ReadFileToString(path));
  auto bad = [&](const std::string& m) { return DataLoss(path + ": " + m); };
  const size_t header_end = data.find("end_header");
  if (data.compare(0, 3, "ply") != 0 || header_end == std::string::npos) return bad("not a PLY file");
  size_t body = data.find('\n', header_end);
  if (body == std::string::npos) return bad("header not terminated");
  ++body;
  std::istringstream header(data.substr(0, header_end));
  std::string line;
  bool ascii = false;
  std::vector<PlyElement> elements;
  while (std::getline(header, line)) {
    std::istringstream ls(line);
    std::string word;
    ls >> word;
    if (word == "format") {
      std::string fmt;
      ls >> fmt;
      if (fmt == "ascii") ascii = true;
      else if (fmt != "binary_little_endian") return bad("unsupported PLY format '" + fmt + "'");
    } else if (word == "element") {
      PlyElement e;
      ls >> e.name >> e.count;
      if (!ls) return bad("malformed element line '" + line + "'");
      elements.push_back(e);
    } else if (word == "property") {
      if (elements.empty()) return bad("property before any element");
      PlyProperty p;
      std::string t;
      ls >> t;
      if (t == "list") {
        std::string ct, it;
        ls >> ct >> it >> p.name;
        p.is_list = true;
        p.count_type = ParsePlyType(ct);
        p.type = ParsePlyType(it);
        if (p.count_type == PlyType::kInvalid || p.type == PlyType::kInvalid) return bad("bad list type in '" + line + "'");
      } else {
        p.type = ParsePlyType(t);
        ls >> p.name;
        if (p.type == PlyType::kInvalid) return bad("unknown property type '" + t + "'");
      }
      elements.back().props.push_back(p);
    }
  }
  bool has_vertex_element = false;
  for (const auto& e : elements) has_vertex_element |= e.name == "vertex";
  if (!has_vertex_element) return bad("no vertex element");
  Mesh mesh;
  PlyValueReader reader(data, body, ascii);
  for (const auto& e : elements) {
    // Every element needs at least one byte (binary) or two chars (ASCII) per item.
    size_t min_item = 0;
    for (const auto& p : e.props) min_item += p.is_list ? PlyTypeSize(p.count_type) : PlyTypeSize(p.type);
    if (ascii) min_item = 2 * e.props.size();
    if (min_item > 0 && e.count > reader.remaining() / min_item)
      return bad("element '" + e.name + "' count " + std::to_string(e.count) + " exceeds the file size");
    // An element without properties has no bytes: nothing to read, whatever its count says.
    if (e.props.empty()) continue;
    const bool is_vertex = e.name == "vertex", is_face = e.name == "face";
    int ix = -1, iy = -1, iz = -1, inx = -1, iny = -1, inz = -1, ir = -1, ig = -1, ib = -1;
    for (size_t k = 0; k < e.props.size(); ++k) {
      const std::string& n = e.props[k].name;
      const int kk = static_cast<int>(k);
      if (n == "x") ix = kk; else if (n == "y") iy = kk; else if (n == "z") iz = kk;
      else if (n == "nx") inx = kk; else if (n == "ny") iny = kk; else if (n == "nz") inz = kk;
      else if (n == "red" || n == "r") ir = kk; else if (n == "green" || n == "g") ig = kk;
      else if (n == "blue" || n == "b") ib = kk;
    }
    if (is_vertex) {
      if (ix < 0 || iy < 0 || iz < 0) return bad("vertex element lacks x, y, z");
      mesh.positions.reserve(e.count);
    }
    const bool has_n = is_vertex && inx >= 0 && iny >= 0 && inz >= 0;
    const bool has_c = is_vertex && ir >= 0 && ig >= 0 && ib >= 0;
    std::vector<double> vals(e.props.size());
    for (uint64_t item = 0; item < e.count; ++item) {
      for (size_t k = 0; k < e.props.size(); ++k) {
        const auto& p = e.props[k];
        if (!p.is_list) {
          if (!reader.Read(p.type, &vals[k])) return bad("truncated in element '" + e.name + "'");
          continue;
        }
        double cnt_d;
        if (!reader.Read(p.count_type, &cnt_d) || !(cnt_d >= 0 && cnt_d <= 1024))  // NaN too (found by fuzzing)
          return bad("bad list length in element '" + e.name + "' item " + std::to_string(item));
        const int cnt = static_cast<int>(cnt_d);
        std::vector<uint32_t> poly(static_cast<size_t>(cnt));
        for (int j = 0; j < cnt; ++j) {
          double v;
          if (!reader.Read(p.type, &v)) return bad("truncated in element '" + e.name + "'");
          if (!(v >= 0 && v <= 4294967295.0)) return bad("negative or huge vertex index in face " + std::to_string(item));
          poly[static_cast<size_t>(j)] = static_cast<uint32_t>(v);
        }
        if (is_face && (p.name == "vertex_indices" || p.name == "vertex_index")) {
          for (int j = 2; j < cnt; ++j) mesh.triangles.push_back({poly[0], poly[static_cast<size_t>(j - 1)], poly[static_cast<size_t>(j)]});
        }
      }
      if (is_vertex) {
        mesh.positions.emplace_back(vals[ix], vals[iy], vals[iz]);
        if (has_n) mesh.normals.emplace_back(vals[inx], vals[iny], vals[inz]);
        if (has_c) {
          auto c8 = [&](int k) {
            const double v = e.props[static_cast<size_t>(k)].type == PlyType::kFloat32 ||
                                     e.props[static_cast<size_t>(k)].type == PlyType::kFloat64
                                 ? vals[k] * 255.0
                                 : vals[k];
            return static_cast<uint8_t>(std::lround(std::clamp(v, 0.0, 255.0)));
          };
          mesh.colors.push_back({c8(ir), c8(ig), c8(ib)});
        }
      }
    }
  }
  HOLO_RETURN_IF_ERROR(mesh.Validate().WithContext(path));
  // Validate() does not look at normals; a file's must be finite too (found by fuzzing).
  for (size_t i = 0; i < mesh.normals.size(); ++i)
    if (!mesh.normals[i].allFinite()) return DataLoss(path + ": normal " + std::to_string(i) + " is not finite");
  return mesh;
}

}  // namespace holo
