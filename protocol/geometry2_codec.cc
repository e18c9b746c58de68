#include "protocol/geometry2_codec.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <span>
#include <unordered_map>

#include "common/metrics/triangle_index.h"
#include "protocol/byte_io.h"
#include "protocol/rans_coder.h"

namespace holo::protocol {
namespace {

using rans::TokenReader;
using rans::TokenWriter;
using rans::UnZigZag;
using rans::ZigZag;

constexpr uint8_t kKindKeyframe = 0;
constexpr uint8_t kKindPredicted = 1;
constexpr int32_t kUnitsPerStep = 16;      // reference position units per keyframe grid step
constexpr int32_t kMaxCoord = 1 << 22;     // reference positions are clamped to ±this (units)
constexpr int32_t kMaxSteps = 4095;        // largest |displacement|, steps
constexpr uint32_t kMaxStepUnits = 4096;   // largest displacement step, units
constexpr uint32_t kContexts = 15;         // 0..7 displacement residuals, 8 motion flag, 9..14 motion
constexpr int32_t kClusterCell = 96 * kUnitsPerStep;  // cluster cube edge, units (96 keyframe steps)
constexpr int32_t kTransUnits = 8;         // motion translation step, units
constexpr int32_t kRotScale = 4096;        // motion rotation: quaternion vector part × this
constexpr int32_t kMaxTrans = kMaxCoord / kTransUnits;
constexpr float kFarCap = 0.05f;           // error samples farther than this count as this, metres

// PROTOCOL.md §7.1 "Reference hash".
uint32_t HashPositions(const std::vector<std::array<int32_t, 3>>& pos) {
  uint64_t h = 14695981039346656037ull;
  for (const auto& p : pos)
    for (int32_t c : p) h = (h ^ static_cast<uint32_t>(c)) * 1099511628211ull;
  return static_cast<uint32_t>(h ^ (h >> 32));
}

// PROTOCOL.md §7.1 "Normals": integer area-weighted face normals summed at the
// corners, one smoothing pass (each vertex sums its triangles' corner sums),
// all in wrapping 64-bit integers; then one sqrt and three divides in double.
void ComputeNormals(const std::vector<std::array<int32_t, 3>>& pos, const std::vector<std::array<uint32_t, 3>>& tris,
                    std::vector<std::array<double, 3>>* out) {
  thread_local std::vector<std::array<uint64_t, 3>> s1, s2;
  const size_t nv = pos.size();
  s1.assign(nv, {0, 0, 0});
  for (const auto& t : tris) {
    const auto &a = pos[t[0]], &b = pos[t[1]], &c = pos[t[2]];
    // |coordinates| ≤ 2^22: edges ≤ 2^23, each product ≤ 2^46, no overflow here.
    const int64_t e1[3] = {int64_t{b[0]} - a[0], int64_t{b[1]} - a[1], int64_t{b[2]} - a[2]};
    const int64_t e2[3] = {int64_t{c[0]} - a[0], int64_t{c[1]} - a[1], int64_t{c[2]} - a[2]};
    const int64_t n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
    for (uint32_t v : t)
      for (int k = 0; k < 3; ++k) s1[v][k] += static_cast<uint64_t>(n[k]);
  }
  s2.assign(nv, {0, 0, 0});
  for (const auto& t : tris) {
    uint64_t s[3];
    for (int k = 0; k < 3; ++k) s[k] = s1[t[0]][k] + s1[t[1]][k] + s1[t[2]][k];
    for (uint32_t v : t)
      for (int k = 0; k < 3; ++k) s2[v][k] += s[k];
  }
  out->resize(nv);
  for (size_t i = 0; i < nv; ++i) {
    const double x = static_cast<double>(static_cast<int64_t>(s2[i][0]));
    const double y = static_cast<double>(static_cast<int64_t>(s2[i][1]));
    const double z = static_cast<double>(static_cast<int64_t>(s2[i][2]));
    const double len2 = x * x + y * y + z * z;
    if (len2 > 0) {
      const double len = std::sqrt(len2);
      (*out)[i] = {x / len, y / len, z / len};
    } else {
      (*out)[i] = {0, 0, 0};
    }
  }
}

// For every vertex, its neighbours (across an edge) with a smaller index,
// ascending, as CSR.
void BuildAdjacency(size_t nv, const std::vector<std::array<uint32_t, 3>>& tris, std::vector<uint32_t>* start,
                    std::vector<uint32_t>* adj) {
  start->assign(nv + 1, 0);
  for (const auto& t : tris)
    for (int e = 0; e < 3; ++e) {
      const uint32_t a = t[e], b = t[(e + 1) % 3];
      if (a != b) ++(*start)[std::max(a, b) + 1];
    }
  for (size_t v = 0; v < nv; ++v) (*start)[v + 1] += (*start)[v];
  adj->assign((*start)[nv], 0);
  std::vector<uint32_t> fill(start->begin(), start->end() - 1);
  for (const auto& t : tris)
    for (int e = 0; e < 3; ++e) {
      const uint32_t a = t[e], b = t[(e + 1) % 3];
      if (a != b) (*adj)[fill[std::max(a, b)]++] = std::min(a, b);
    }
  // Sort and deduplicate each list, compacting in place.
  uint32_t w = 0;
  for (size_t v = 0; v < nv; ++v) {
    const uint32_t b = (*start)[v], e = (*start)[v + 1];
    std::sort(adj->begin() + b, adj->begin() + e);
    (*start)[v] = w;
    for (uint32_t i = b; i < e; ++i)
      if (i == b || (*adj)[i] != (*adj)[i - 1]) (*adj)[w++] = (*adj)[i];
  }
  (*start)[nv] = w;
  adj->resize(w);
}

// PROTOCOL.md §7.1 "Clusters": the keyframe's vertices grouped by connected
// component and by cube of kClusterCell units, as CSR lists of vertices;
// clusters ordered by their smallest vertex, the vertices of each ascending.
void BuildClusters(const std::vector<std::array<int32_t, 3>>& pos, const std::vector<std::array<uint32_t, 3>>& tris,
                   std::vector<uint32_t>* start, std::vector<uint32_t>* verts, std::vector<uint32_t>* root_of) {
  const size_t nv = pos.size();
  std::vector<uint32_t> parent(nv);
  for (size_t v = 0; v < nv; ++v) parent[v] = static_cast<uint32_t>(v);
  auto find = [&](uint32_t v) {
    while (parent[v] != v) v = parent[v] = parent[parent[v]];
    return v;
  };
  for (const auto& t : tris)
    for (int e = 1; e < 3; ++e) {
      const uint32_t a = find(t[0]), b = find(t[e]);
      if (a != b) parent[std::max(a, b)] = std::min(a, b);  // the root is the smallest vertex
    }
  // Cluster = (component root, cell of the keyframe grid): keyframe positions
  // are 0..65535·16, so a cell index is below 2^10 and a root below 2^22.
  std::unordered_map<uint64_t, uint32_t> id_of;
  std::vector<uint32_t> label(nv);
  root_of->clear();
  uint32_t n = 0;
  for (size_t v = 0; v < nv; ++v) {
    uint64_t key = find(static_cast<uint32_t>(v));
    for (int k = 0; k < 3; ++k) key = (key << 10) | static_cast<uint64_t>(pos[v][k] / kClusterCell);
    auto [it, added] = id_of.emplace(key, n);
    if (added) {
      ++n;
      root_of->push_back(find(static_cast<uint32_t>(v)));
    }
    label[v] = it->second;
  }
  start->assign(n + 1, 0);
  for (size_t v = 0; v < nv; ++v) ++(*start)[label[v] + 1];
  for (uint32_t c = 0; c < n; ++c) (*start)[c + 1] += (*start)[c];
  verts->assign(nv, 0);
  std::vector<uint32_t> fill(start->begin(), start->end() - 1);
  for (size_t v = 0; v < nv; ++v) (*verts)[fill[label[v]]++] = static_cast<uint32_t>(v);
}

// A rigid motion of one component on the wire (PROTOCOL.md §7.1 "Rigid motions").
struct RigidMotion {
  uint32_t component = 0;    // the cluster
  int32_t t[3] = {0, 0, 0};  // translation, kTransUnits units
  int32_t q[3] = {0, 0, 0};  // quaternion vector part × kRotScale
};

// PROTOCOL.md §7.1 "Rigid motions": P' = c + t + round(R (P − c)), c the
// component's truncated integer centroid, R from the quaternion.
void ApplyRigid(const Geometry2Reference& ref, const RigidMotion& m, std::vector<std::array<int32_t, 3>>* pos) {
  const uint32_t b = ref.comp_start[m.component], e = ref.comp_start[m.component + 1];
  const auto n = static_cast<int64_t>(e - b);
  int64_t sum[3] = {0, 0, 0};
  for (uint32_t i = b; i < e; ++i)
    for (int k = 0; k < 3; ++k) sum[k] += (*pos)[ref.comp_verts[i]][k];
  int64_t c[3];
  for (int k = 0; k < 3; ++k) c[k] = sum[k] / n;
  const double x = m.q[0] / static_cast<double>(kRotScale), y = m.q[1] / static_cast<double>(kRotScale),
               z = m.q[2] / static_cast<double>(kRotScale);
  const double w2 = 1.0 - ((x * x + y * y) + z * z);
  const double w = w2 > 0 ? std::sqrt(w2) : 0.0;
  const double r[3][3] = {{1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - z * w), 2.0 * (x * z + y * w)},
                          {2.0 * (x * y + z * w), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - x * w)},
                          {2.0 * (x * z - y * w), 2.0 * (y * z + x * w), 1.0 - 2.0 * (x * x + y * y)}};
  for (uint32_t i = b; i < e; ++i) {
    std::array<int32_t, 3>& p = (*pos)[ref.comp_verts[i]];
    const double d[3] = {static_cast<double>(p[0] - c[0]), static_cast<double>(p[1] - c[1]),
                         static_cast<double>(p[2] - c[2])};
    for (int k = 0; k < 3; ++k) {
      const long long rot = std::llround((r[k][0] * d[0] + r[k][1] * d[1]) + r[k][2] * d[2]);
      p[k] = static_cast<int32_t>(
          std::clamp<long long>(c[k] + int64_t{m.t[k]} * kTransUnits + rot, -kMaxCoord, kMaxCoord));
    }
  }
}

// PROTOCOL.md §7.1 "Prediction": the rounded mean of the decoded neighbours'
// displacements; context from the mean magnitude of their residuals.
inline void Predict(const Geometry2Reference& ref, const int32_t* k, const int32_t* absres, uint32_t v, int32_t* pred,
                    uint32_t* ctx) {
  const uint32_t b = ref.adj_start[v], e = ref.adj_start[v + 1];
  const int64_t c = e - b;
  if (c == 0) {
    *pred = 0;
    *ctx = 0;
    return;
  }
  int64_t s = 0, a = 0;
  for (uint32_t i = b; i < e; ++i) {
    s += k[ref.adj[i]];
    a += absres[ref.adj[i]];
  }
  *pred = static_cast<int32_t>(s >= 0 ? (s + c / 2) / c : -((-s + c / 2) / c));
  const auto mean_abs = static_cast<uint64_t>((a + c - 1) / c);
  *ctx = 1 + std::min<uint32_t>(static_cast<uint32_t>(std::bit_width(mean_abs)), 6);
}

// PROTOCOL.md §7.1 "Update": position += round(k · step · normal), clamped.
void ApplyDisplacements(const std::vector<std::array<double, 3>>& normals, const std::vector<int32_t>& k,
                        int32_t step_units, std::vector<std::array<int32_t, 3>>* pos) {
  const size_t nv = pos->size();
  for (size_t i = 0; i < nv; ++i) {
    if (k[i] == 0) continue;
    std::array<int32_t, 3>& p = (*pos)[i];
    const double d = static_cast<double>(int64_t{k[i]} * step_units);
    for (int c = 0; c < 3; ++c) {
      const long long delta = std::llround(d * normals[i][c]);
      p[c] = static_cast<int32_t>(std::clamp<long long>(p[c] + delta, -kMaxCoord, kMaxCoord));
    }
  }
}

// The reference of a keyframe: the decoded G1 mesh `m` and the grid of its
// blob `g1` (origin at byte 12, step at byte 24, PROTOCOL.md §7).
Status ReferenceFromKeyframe(std::span<const uint8_t> g1, const Mesh& m, uint32_t id, Geometry2Reference* ref) {
  ByteReader r(g1.subspan(std::min<size_t>(12, g1.size())));
  float origin[3], step = 0;
  for (float& f : origin) HOLO_RETURN_IF_ERROR(r.F32("g2.keyframe.origin", &f));
  HOLO_RETURN_IF_ERROR(r.F32("g2.keyframe.step", &step));
  ref->valid = false;
  ref->keyframe_id = id;
  ref->frame_index = 0;
  std::copy(origin, origin + 3, ref->origin);
  ref->unit = step / static_cast<float>(kUnitsPerStep);
  const size_t nv = m.num_vertices();
  ref->pos.resize(nv);
  for (size_t v = 0; v < nv; ++v)
    for (int c = 0; c < 3; ++c) {
      // Decoded G1 positions are origin + step·q exactly; this recovers q.
      const long q = std::lround((m.positions[v][c] - origin[c]) / step);
      if (q < 0 || q > 65535) return DataLoss("g2.keyframe: vertex " + Str(v) + " is off the G1 grid");
      ref->pos[v][c] = static_cast<int32_t>(q) * kUnitsPerStep;
    }
  ref->triangles = m.triangles;
  ref->colors = m.colors;
  ComputeNormals(ref->pos, ref->triangles, &ref->normals);
  BuildAdjacency(nv, ref->triangles, &ref->adj_start, &ref->adj);
  BuildClusters(ref->pos, ref->triangles, &ref->comp_start, &ref->comp_verts, &ref->cluster_root);
  ref->hash = HashPositions(ref->pos);
  ref->valid = true;
  return OkStatus();
}

void WriteHeader(ByteWriter& w, uint8_t kind, uint32_t id, uint32_t index, uint32_t nv) {
  w.U8(kG2CodecId);
  w.U8(kind);
  w.U16(0);
  w.U32(id);
  w.U32(index);
  w.U32(nv);
}

Status ReadHeader(ByteReader& r, Geometry2BlobInfo* info) {
  uint8_t codec = 0, kind = 0;
  uint16_t reserved = 0;
  HOLO_RETURN_IF_ERROR(r.U8("g2.codec", &codec));
  if (codec != kG2CodecId) return DataLoss("g2.codec: " + Str(codec) + " is not G2 (3)");
  HOLO_RETURN_IF_ERROR(r.U8("g2.kind", &kind));
  if (kind != kKindKeyframe && kind != kKindPredicted) return DataLoss("g2.kind: " + Str(kind) + " is neither 0 nor 1");
  HOLO_RETURN_IF_ERROR(r.U16("g2.reserved", &reserved));
  if (reserved != 0) return DataLoss("g2.reserved: must be zero");
  HOLO_RETURN_IF_ERROR(r.U32("g2.keyframe_id", &info->keyframe_id));
  HOLO_RETURN_IF_ERROR(r.U32("g2.frame_index", &info->frame_index));
  HOLO_RETURN_IF_ERROR(r.U32("g2.num_vertices", &info->num_vertices));
  info->keyframe = kind == kKindKeyframe;
  if (info->keyframe != (info->frame_index == 0)) {
    return DataLoss("g2.frame_index: " + Str(info->frame_index) + (info->keyframe ? " on a keyframe (must be 0)" : " on a predicted frame (must be ≥ 1)"));
  }
  return OkStatus();
}

Eigen::Vector3f FaceNormal(const Eigen::Vector3f& a, const Eigen::Vector3f& b, const Eigen::Vector3f& c) {
  const Eigen::Vector3f n = (b - a).cross(c - a);
  const float len = n.norm();
  return len > 0 ? Eigen::Vector3f(n / len) : Eigen::Vector3f::Zero();
}

// Point-to-plane ICP of one component of the reference (float positions
// `fpos`, unit normals `fnrm`) onto the new mesh: the motion
// p → R (p − g) + g + t about the component's centroid g. False if the
// component does not find enough of the new surface or the motion does not
// bring it closer.
bool EstimateRigid(std::span<const uint32_t> verts, std::span<const float> radii,
                   const std::vector<Eigen::Vector3f>& fpos, const std::vector<Eigen::Vector3f>& fnrm,
                   const metrics::TriangleIndex& index, const Mesh& mesh, Eigen::Matrix3d* R, Eigen::Vector3d* g,
                   Eigen::Vector3d* t) {
  const uint32_t b = 0, e = static_cast<uint32_t>(verts.size());
  if (e == 0) return false;
  const uint32_t stride = std::max<uint32_t>(1, e / 1500);
  // The initial motion (*R, *t about *g) re-expressed about this set's centroid.
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (uint32_t v : verts) c += fpos[v].cast<double>();
  c /= static_cast<double>(e);
  *t = *R * (c - *g) + *g + *t - c;
  *g = c;
  const Eigen::Matrix3d R0 = *R;
  const Eigen::Vector3d t0 = *t;
  struct RefView {
    std::span<const uint32_t> comp_verts;
  } ref{verts};
  // Capped squared distance of the samples under the current motion.
  auto cost = [&](const Eigen::Matrix3d& r, const Eigen::Vector3d& tr) {
    double se = 0;
    for (uint32_t i = b; i < e; i += stride) {
      const Eigen::Vector3d p = r * (fpos[ref.comp_verts[i]].cast<double>() - *g) + *g + tr;
      const float d = std::min(index.Query(p.cast<float>(), 0.03f).distance, 0.03f);
      se += double{d} * d;
    }
    return se;
  };
  for (float radius : radii) {
    Eigen::Matrix<double, 6, 6> A = Eigen::Matrix<double, 6, 6>::Zero();
    Eigen::Matrix<double, 6, 1> rhs = Eigen::Matrix<double, 6, 1>::Zero();
    int count = 0;
    for (uint32_t i = b; i < e; i += stride) {
      const uint32_t v = ref.comp_verts[i];
      if (fnrm[v].isZero()) continue;
      const Eigen::Vector3d pc = *R * (fpos[v].cast<double>() - *g);
      const Eigen::Vector3d p = pc + *g + *t;
      const Eigen::Vector3d n = *R * fnrm[v].cast<double>();
      const metrics::ClosestPoint q = index.Query(p.cast<float>(), radius);
      if (!q.found()) continue;
      const auto& tr = mesh.triangles[q.triangle];
      const Eigen::Vector3d m =
          FaceNormal(mesh.positions[tr[0]], mesh.positions[tr[1]], mesh.positions[tr[2]]).cast<double>();
      if (!(n.dot(m) >= 0.3)) continue;
      Eigen::Matrix<double, 6, 1> J;
      J << pc.cross(m), m;
      A += J * J.transpose();
      rhs += J * (q.point.cast<double>() - p).dot(m);
      ++count;
    }
    if (count < 6) return false;
    // A little damping: a ball's rotation is not observable from its shape.
    A += 1e-4 * count * 1e-2 * Eigen::Matrix<double, 6, 6>::Identity();
    const Eigen::Matrix<double, 6, 1> x = A.ldlt().solve(rhs);
    if (!x.allFinite()) return false;
    const Eigen::Vector3d w = x.head<3>();
    const double angle = w.norm();
    const Eigen::Matrix3d dR =
        angle > 0 ? Eigen::AngleAxisd(angle, w / angle).toRotationMatrix() : Eigen::Matrix3d::Identity();
    *R = dR * *R;
    *t = dR * *t + x.tail<3>();
  }
  const double before = cost(R0, t0), after = cost(*R, *t);
  if (!(after < 0.9 * before)) {
    *R = R0;
    *t = t0;
    return false;
  }
  return true;
}

struct EncoderScratch {
  Mesh decoded;
  std::vector<Eigen::Vector3f> fnrm;
  std::vector<float> target, smoothed;
  std::vector<int32_t> k, absres;
  std::vector<std::array<int32_t, 3>> pos;
  std::vector<std::array<double, 3>> normals, rigid_normals;
  std::vector<RigidMotion> motions;
  std::vector<uint16_t> syms;
  std::vector<uint8_t> coded, g1;
};
EncoderScratch& Scratch() {
  thread_local EncoderScratch s;
  return s;
}

}  // namespace

void Geometry2Reference::ToMesh(Mesh* mesh) const {
  const size_t nv = pos.size();
  mesh->positions.resize(nv);
  mesh->normals.resize(nv);
  for (size_t v = 0; v < nv; ++v) {
    for (int c = 0; c < 3; ++c) mesh->positions[v][c] = origin[c] + static_cast<float>(pos[v][c]) * unit;
    const auto& n = normals[v];
    mesh->normals[v] = n[0] == 0 && n[1] == 0 && n[2] == 0
                           ? Eigen::Vector3f::UnitZ()
                           : Eigen::Vector3f(static_cast<float>(n[0]), static_cast<float>(n[1]), static_cast<float>(n[2]));
  }
  mesh->colors = colors;
  mesh->triangles = triangles;
}

Status Geometry2EncodeOptions::Check() const {
  HOLO_RETURN_IF_ERROR(keyframe.Check());
  if (keyframe.codec != GeometryCodec::kG1) return InvalidArgument("keyframe.codec must be G1");
  if (!(displacement_step_m >= keyframe.position_step_m / kUnitsPerStep && displacement_step_m <= 0.01f)) {
    return InvalidArgument("displacement_step_m must be in [keyframe step / 16, 0.01], got " +
                           std::to_string(displacement_step_m));
  }
  if (!(dead_zone_steps >= 0.5f && dead_zone_steps <= 4.0f)) {
    return InvalidArgument("dead_zone_steps must be in [0.5, 4], got " + std::to_string(dead_zone_steps));
  }
  if (!(max_displacement_m > 0 && max_displacement_m <= 0.2f)) {
    return InvalidArgument("max_displacement_m must be in (0, 0.2], got " + std::to_string(max_displacement_m));
  }
  if (!(max_rms_m > 0) || !(far_m > 0) || !(max_far_fraction >= 0 && max_far_fraction <= 1) ||
      !(max_flipped_fraction >= 0 && max_flipped_fraction <= 1)) {
    return InvalidArgument("max_rms_m and far_m must be > 0, max_far_fraction and max_flipped_fraction in [0, 1]");
  }
  if (rigid_min_vertices < 0) return InvalidArgument("rigid_min_vertices must be ≥ 0");
  if (smooth_passes < 0 || smooth_passes > 8) {
    return InvalidArgument("smooth_passes must be in [0, 8], got " + std::to_string(smooth_passes));
  }
  if (max_group_frames < 1 || max_group_frames > 65535) {
    return InvalidArgument("max_group_frames must be in [1, 65535], got " + std::to_string(max_group_frames));
  }
  return OkStatus();
}

Geometry2Encoder::Geometry2Encoder(const Geometry2EncodeOptions& options) : options_(options), status_(options.Check()) {}

Status Geometry2Encoder::EncodeKeyframe(const Mesh& mesh, std::vector<uint8_t>* out) {
  EncoderScratch& sc = Scratch();
  GeometryEncodeOptions ko = options_.keyframe;
  ko.normals = NormalMode::kNone;  // G2 computes its own
  sc.g1.clear();
  HOLO_RETURN_IF_ERROR(EncodeGeometry(mesh, ko, &sc.g1));
  if (Status s = DecodeGeometry(sc.g1, &sc.decoded); !s.ok()) {
    return InvalidArgument("keyframe does not decode within the protocol limits: " + s.message());
  }
  Geometry2Reference ref;
  HOLO_RETURN_IF_ERROR(ReferenceFromKeyframe(sc.g1, sc.decoded, next_keyframe_id_, &ref));
  ++next_keyframe_id_;
  ByteWriter w(out);
  WriteHeader(w, kKindKeyframe, ref.keyframe_id, 0, static_cast<uint32_t>(ref.pos.size()));
  w.Bytes(sc.g1);
  ref_ = std::move(ref);
  key_face_normals_.resize(ref_.triangles.size());
  key_area_ = 0;
  for (size_t t = 0; t < ref_.triangles.size(); ++t) {
    const auto& tr = ref_.triangles[t];
    const Eigen::Vector3f& a = sc.decoded.positions[tr[0]];
    // Area-weighted (twice the area): slivers that turn over do not count.
    key_face_normals_[t] = (sc.decoded.positions[tr[1]] - a).cross(sc.decoded.positions[tr[2]] - a);
    key_area_ += key_face_normals_[t].norm();
  }
  // The clusters of every component (components in order of their root).
  {
    std::vector<uint32_t> order(ref_.cluster_root.size());
    for (uint32_t c = 0; c < order.size(); ++c) order[c] = c;
    std::stable_sort(order.begin(), order.end(),
                     [&](uint32_t a, uint32_t b) { return ref_.cluster_root[a] < ref_.cluster_root[b]; });
    comp_clusters_ = order;
    comp_clusters_start_.assign(1, 0);
    for (uint32_t j = 1; j <= order.size(); ++j) {
      if (j == order.size() || ref_.cluster_root[order[j]] != ref_.cluster_root[order[j - 1]]) {
        comp_clusters_start_.push_back(j);
      }
    }
    if (order.empty()) comp_clusters_start_.assign(1, 0);
  }
  // Every vertex's one-ring, for the encoder's smoothing.
  {
    const size_t nv = ref_.pos.size();
    ring_start_.assign(nv + 1, 0);
    for (const auto& t : ref_.triangles)
      for (int e = 0; e < 3; ++e) ++ring_start_[t[e] + 1];
    for (size_t v = 0; v < nv; ++v) ring_start_[v + 1] += ring_start_[v];
    ring_.assign(ring_start_[nv], 0);
    std::vector<uint32_t> fill(ring_start_.begin(), ring_start_.end() - 1);
    // Each corner lists the next corner of its triangle: over a closed fan
    // that is every neighbour once (open fans miss one; good enough here).
    for (const auto& t : ref_.triangles)
      for (int e = 0; e < 3; ++e) ring_[fill[t[e]]++] = t[(e + 1) % 3];
  }
  force_keyframe_ = false;
  return OkStatus();
}

StatusOr<std::string> Geometry2Encoder::TryPredicted(const Mesh& mesh, std::vector<uint8_t>* out,
                                                     Geometry2FrameInfo* info) {
  EncoderScratch& sc = Scratch();
  const Geometry2EncodeOptions& o = options_;
  HOLO_ASSIGN_OR_RETURN(const metrics::TriangleIndex index, metrics::TriangleIndex::Build(mesh));
  ref_.ToMesh(&sc.decoded);
  const size_t nv = ref_.pos.size();
  const float maxd = o.max_displacement_m;

  // Rigid motions of the components that move as a whole.
  sc.pos = ref_.pos;
  sc.motions.clear();
  const auto ncomp = static_cast<uint32_t>(ref_.comp_start.size() - 1);
  if (o.rigid_min_vertices > 0) {
    sc.fnrm.resize(nv);
    for (size_t v = 0; v < nv; ++v)
      sc.fnrm[v] = Eigen::Vector3f(static_cast<float>(ref_.normals[v][0]), static_cast<float>(ref_.normals[v][1]),
                                   static_cast<float>(ref_.normals[v][2]));
    // Whole components first (a ball, a prop, a person turning), then every
    // cluster of a component from its component's motion (limbs); a cluster
    // that finds nothing better keeps the component's motion.
    static constexpr float kWide[] = {0.15f, 0.12f, 0.09f, 0.06f, 0.04f, 0.03f, 0.02f, 0.02f};
    static constexpr float kNarrow[] = {0.04f, 0.03f, 0.02f, 0.02f};
    std::vector<uint32_t> members;
    for (size_t comp = 0; comp + 1 < comp_clusters_start_.size(); ++comp) {
      members.clear();
      for (uint32_t j = comp_clusters_start_[comp]; j < comp_clusters_start_[comp + 1]; ++j) {
        const uint32_t cl = comp_clusters_[j];
        members.insert(members.end(), ref_.comp_verts.begin() + ref_.comp_start[cl],
                       ref_.comp_verts.begin() + ref_.comp_start[cl + 1]);
      }
      Eigen::Matrix3d Rc = Eigen::Matrix3d::Identity();
      Eigen::Vector3d gc = Eigen::Vector3d::Zero(), tc = Eigen::Vector3d::Zero();
      bool comp_moved = false;
      if (members.size() >= static_cast<size_t>(o.rigid_min_vertices)) {
        comp_moved = EstimateRigid(members, kWide, sc.decoded.positions, sc.fnrm, index, mesh, &Rc, &gc, &tc);
      }
      for (uint32_t j = comp_clusters_start_[comp]; j < comp_clusters_start_[comp + 1]; ++j) {
        const uint32_t c = comp_clusters_[j];
        Eigen::Matrix3d R = Rc;
        Eigen::Vector3d g = gc, t = tc;
        const std::span<const uint32_t> verts(ref_.comp_verts.data() + ref_.comp_start[c],
                                              ref_.comp_start[c + 1] - ref_.comp_start[c]);
        bool moved = comp_moved;
        if (verts.size() >= 6) moved |= EstimateRigid(verts, comp_moved ? std::span<const float>(kNarrow) : std::span<const float>(kWide),
                                                     sc.decoded.positions, sc.fnrm, index, mesh, &R, &g, &t);
        if (!moved) continue;
      // The same motion about the decoder's pivot: the truncated integer centroid.
      const uint32_t b = ref_.comp_start[c], e = ref_.comp_start[c + 1];
      int64_t sum[3] = {0, 0, 0};
      for (uint32_t i = b; i < e; ++i)
        for (int k = 0; k < 3; ++k) sum[k] += ref_.pos[ref_.comp_verts[i]][k];
      Eigen::Vector3d cm;
      for (int k = 0; k < 3; ++k) {
        cm[k] = ref_.origin[k] + static_cast<double>(sum[k] / static_cast<int64_t>(e - b)) * ref_.unit;
      }
      const Eigen::Vector3d tw = R * (cm - g) + g + t - cm;
      Eigen::Quaterniond q(R);
      if (q.w() < 0) q.coeffs() = -q.coeffs();
      RigidMotion m;
      m.component = c;
      bool moves = false;
      for (int k = 0; k < 3; ++k) {
        m.t[k] = static_cast<int32_t>(
            std::clamp<long long>(std::llround(tw[k] / ref_.unit / kTransUnits), -kMaxTrans, kMaxTrans));
        m.q[k] = static_cast<int32_t>(std::clamp<long long>(std::llround(q.vec()[k] * kRotScale), -kRotScale, kRotScale));
        moves |= m.t[k] != 0 || m.q[k] != 0;
      }
      if (!moves) continue;
      ApplyRigid(ref_, m, &sc.pos);
      sc.motions.push_back(m);
      }
    }
    std::sort(sc.motions.begin(), sc.motions.end(),
              [](const RigidMotion& a, const RigidMotion& b) { return a.component < b.component; });
  }
  if (sc.motions.empty()) {
    sc.rigid_normals = ref_.normals;
  } else {
    ComputeNormals(sc.pos, ref_.triangles, &sc.rigid_normals);
    for (size_t v = 0; v < nv; ++v)
      for (int c = 0; c < 3; ++c)
        sc.decoded.positions[v][c] = ref_.origin[c] + static_cast<float>(sc.pos[v][c]) * ref_.unit;
  }

  // Target displacement of every reference vertex along its normal: a
  // ray–plane step onto the nearest triangle of the new mesh, twice (NaN: no
  // surface facing the same way within reach).
  sc.target.assign(nv, std::numeric_limits<float>::quiet_NaN());
  for (size_t v = 0; v < nv; ++v) {
    const auto& nd = sc.rigid_normals[v];
    if (nd[0] == 0 && nd[1] == 0 && nd[2] == 0) continue;
    const Eigen::Vector3f n(static_cast<float>(nd[0]), static_cast<float>(nd[1]), static_cast<float>(nd[2]));
    const Eigen::Vector3f& p = sc.decoded.positions[v];
    float t = 0;
    bool hit = false;
    for (int iter = 0; iter < 2; ++iter) {
      const Eigen::Vector3f at = p + t * n;
      const metrics::ClosestPoint q = index.Query(at, maxd);
      if (!q.found()) break;
      const auto& tr = mesh.triangles[q.triangle];
      const Eigen::Vector3f m = FaceNormal(mesh.positions[tr[0]], mesh.positions[tr[1]], mesh.positions[tr[2]]);
      const float denom = n.dot(m);
      if (!(denom >= 0.3f)) break;  // the nearest surface faces elsewhere (e.g. the far side of a thin part)
      t = std::clamp(t + (q.point - at).dot(m) / denom, -maxd, maxd);
      hit = true;
    }
    if (hit) sc.target[v] = t;
  }

  // Low-pass the targets over each one-ring (valid targets only): a re-fused
  // surface ripples by fractions of a millimetre from frame to frame, and
  // following that noise vertex by vertex costs bits and turns slivers over.
  for (int pass = 0; pass < o.smooth_passes; ++pass) {
    sc.smoothed.resize(nv);
    for (size_t v = 0; v < nv; ++v) {
      if (std::isnan(sc.target[v])) {
        sc.smoothed[v] = sc.target[v];
        continue;
      }
      float sum = sc.target[v];
      int n = 1;
      for (uint32_t i = ring_start_[v]; i < ring_start_[v + 1]; ++i) {
        const float t = sc.target[ring_[i]];
        if (!std::isnan(t)) {
          sum += t;
          ++n;
        }
      }
      sc.smoothed[v] = sum / static_cast<float>(n);
    }
    sc.target.swap(sc.smoothed);
  }

  // Quantize in vertex order against the neighbours' prediction, exactly as
  // the decoder will reconstruct.
  const auto step_units = static_cast<int32_t>(
      std::clamp<long>(std::lround(o.displacement_step_m / ref_.unit), 1, static_cast<long>(kMaxStepUnits)));
  const float step_m = static_cast<float>(step_units) * ref_.unit;
  sc.k.assign(nv, 0);
  sc.absres.assign(nv, 0);
  TokenWriter tw(kContexts, nv + ncomp, &sc.syms);
  {  // PROTOCOL.md §7.1 "Motions": per cluster a flag, then the motion as deltas to the last one sent
    RigidMotion last;
    size_t next = 0;
    for (uint32_t c = 0; c < ncomp; ++c) {
      const bool moved = next < sc.motions.size() && sc.motions[next].component == c;
      tw.PutValue(8, moved ? 1 : 0);
      if (!moved) continue;
      const RigidMotion& m = sc.motions[next++];
      for (int k = 0; k < 3; ++k) tw.PutValue(9 + k, ZigZag(m.t[k] - last.t[k]));
      for (int k = 0; k < 3; ++k) tw.PutValue(12 + k, ZigZag(m.q[k] - last.q[k]));
      last = m;
    }
  }
  for (uint32_t v = 0; v < nv; ++v) {
    int32_t pred = 0;
    uint32_t ctx = 0;
    Predict(ref_, sc.k.data(), sc.absres.data(), v, &pred, &ctx);
    int32_t r = 0;
    if (!std::isnan(sc.target[v])) {
      const float x = sc.target[v] / step_m - static_cast<float>(pred);
      if (std::fabs(x) >= o.dead_zone_steps) r = static_cast<int32_t>(std::lround(x));
      r = std::clamp(r, -kMaxSteps - pred, kMaxSteps - pred);
    }
    sc.k[v] = pred + r;
    sc.absres[v] = std::abs(r);
    tw.PutValue(ctx, ZigZag(r));
  }
  ApplyDisplacements(sc.rigid_normals, sc.k, step_units, &sc.pos);
  ComputeNormals(sc.pos, ref_.triangles, &sc.normals);

  // Check the frame the decoder would show against the input, both ways.
  for (size_t v = 0; v < nv; ++v)
    for (int c = 0; c < 3; ++c)
      sc.decoded.positions[v][c] = ref_.origin[c] + static_cast<float>(sc.pos[v][c]) * ref_.unit;
  double se = 0, mx = 0;
  size_t far = 0;
  for (size_t v = 0; v < nv; ++v) {
    const float d = std::min(index.Query(sc.decoded.positions[v], kFarCap).distance, kFarCap);
    se += double{d} * d;
    mx = std::max<double>(mx, d);
    far += d > o.far_m;
  }
  HOLO_ASSIGN_OR_RETURN(const metrics::TriangleIndex back, metrics::TriangleIndex::Build(sc.decoded));
  for (const Eigen::Vector3f& p : mesh.positions) {
    const float d = std::min(back.Query(p, kFarCap).distance, kFarCap);
    se += double{d} * d;
    mx = std::max<double>(mx, d);
    far += d > o.far_m;
  }
  const double samples = static_cast<double>(nv + mesh.num_vertices());
  double flipped = 0;
  for (size_t t = 0; t < ref_.triangles.size(); ++t) {
    const auto& tr = ref_.triangles[t];
    const Eigen::Vector3f& a = sc.decoded.positions[tr[0]];
    const Eigen::Vector3f n = (sc.decoded.positions[tr[1]] - a).cross(sc.decoded.positions[tr[2]] - a);
    if (n.dot(key_face_normals_[t]) < 0) flipped += key_face_normals_[t].norm();
  }
  info->rms_m = samples > 0 ? std::sqrt(se / samples) : 0;
  info->max_m = mx;
  info->far_fraction = samples > 0 ? static_cast<double>(far) / samples : 0;
  info->flipped_fraction = key_area_ > 0 ? flipped / key_area_ : 0;
  if (info->rms_m > o.max_rms_m) return std::string("rms");
  if (info->far_fraction > o.max_far_fraction) return std::string("far");
  if (info->flipped_fraction > o.max_flipped_fraction) return std::string("flipped");

  ByteWriter w(out);
  WriteHeader(w, kKindPredicted, ref_.keyframe_id, ref_.frame_index + 1, static_cast<uint32_t>(nv));
  w.U32(ref_.hash);
  w.U16(static_cast<uint16_t>(step_units));
  w.U16(0);
  sc.coded.clear();
  tw.Finish(&sc.coded);
  w.Bytes(sc.coded);
  ref_.pos.swap(sc.pos);
  ref_.normals.swap(sc.normals);
  ref_.hash = HashPositions(ref_.pos);
  ++ref_.frame_index;
  info->keyframe_id = ref_.keyframe_id;
  info->frame_index = ref_.frame_index;
  return std::string();
}

Status Geometry2Encoder::Encode(const Mesh& mesh, std::vector<uint8_t>* out, Geometry2FrameInfo* info) {
  HOLO_RETURN_IF_ERROR(status_);
  if (Status s = CheckMesh(mesh); !s.ok()) return InvalidArgument(s.message());
  Geometry2FrameInfo local;
  if (info == nullptr) info = &local;
  *info = {};
  std::string reason;
  if (!ref_.valid) {
    reason = "first";
  } else if (force_keyframe_) {
    reason = "requested";
  } else if (ref_.frame_index + 1 >= static_cast<uint32_t>(options_.max_group_frames)) {
    reason = "group-length";
  } else if (mesh.triangles.empty() || ref_.triangles.empty()) {
    reason = "empty";
  } else if (skip_left_ > 0) {
    --skip_left_;
    reason = "backoff";
  } else {
    const bool right_after_keyframe = ref_.frame_index == 0;
    HOLO_ASSIGN_OR_RETURN(reason, TryPredicted(mesh, out, info));
    if (reason.empty()) {
      failures_after_keyframe_ = 0;
      return OkStatus();
    }
    // Content that cannot be predicted even one frame after a keyframe (a
    // flickering mesh) costs the attempt every frame: back off, 1, 3, 7, 15
    // frames, until a prediction succeeds again.
    if (right_after_keyframe && options_.backoff) {
      failures_after_keyframe_ = std::min(failures_after_keyframe_ + 1, 4);
      skip_left_ = (1 << failures_after_keyframe_) - 1;
    }
  }
  const Geometry2FrameInfo tried = *info;
  info->keyframe = true;
  info->reason = reason;
  HOLO_RETURN_IF_ERROR(EncodeKeyframe(mesh, out));
  info->keyframe_id = ref_.keyframe_id;
  info->frame_index = 0;
  info->rms_m = tried.rms_m;
  info->max_m = tried.max_m;
  info->far_fraction = tried.far_fraction;
  info->flipped_fraction = tried.flipped_fraction;
  return OkStatus();
}

StatusOr<Geometry2BlobInfo> PeekGeometry2(std::span<const uint8_t> blob) {
  ByteReader r(blob);
  Geometry2BlobInfo info;
  HOLO_RETURN_IF_ERROR(ReadHeader(r, &info));
  return info;
}

Status Geometry2Decoder::Decode(std::span<const uint8_t> blob, Mesh* mesh, const Limits& limits) {
  ClearMesh(mesh);
  ByteReader r(blob);
  Geometry2BlobInfo h;
  HOLO_RETURN_IF_ERROR(ReadHeader(r, &h));
  if (h.num_vertices > limits.max_vertices) {
    return DataLoss("g2.num_vertices: " + Str(h.num_vertices) + " exceeds limit " + Str(limits.max_vertices));
  }
  const std::span<const uint8_t> rest = blob.subspan(r.position());
  if (h.keyframe) {
    if (rest.empty() || rest[0] != static_cast<uint8_t>(GeometryCodec::kG1)) {
      return DataLoss("g2.keyframe: not a G1 blob");
    }
    Mesh& m = *mesh;
    if (Status s = DecodeGeometry(rest, &m, limits); !s.ok()) return DataLoss("g2.keyframe: " + s.message());
    if (m.num_vertices() != h.num_vertices) {
      ClearMesh(mesh);
      return DataLoss("g2.num_vertices: " + Str(h.num_vertices) + " but the keyframe has " + Str(m.num_vertices()));
    }
    if (Status s = ReferenceFromKeyframe(rest, m, h.keyframe_id, &next_); !s.ok()) {
      ClearMesh(mesh);
      return s;
    }
    std::swap(ref_, next_);
    ref_.ToMesh(mesh);
    return OkStatus();
  }

  uint32_t hash = 0;
  uint16_t step_units = 0, reserved = 0;
  HOLO_RETURN_IF_ERROR(r.U32("g2.reference_hash", &hash));
  HOLO_RETURN_IF_ERROR(r.U16("g2.step_units", &step_units));
  HOLO_RETURN_IF_ERROR(r.U16("g2.reserved2", &reserved));
  if (step_units < 1 || step_units > kMaxStepUnits) {
    return DataLoss("g2.step_units: " + Str(step_units) + " not in 1.." + Str(kMaxStepUnits));
  }
  if (reserved != 0) return DataLoss("g2.reserved2: must be zero");
  const std::string frame =
      "g2: predicted frame " + Str(h.frame_index) + " of keyframe " + Str(h.keyframe_id);
  if (!ref_.valid) return NotFound(frame + " needs its reference, and this decoder has no keyframe yet");
  if (h.keyframe_id != ref_.keyframe_id) {
    return NotFound(frame + " does not follow this decoder's keyframe " + Str(ref_.keyframe_id) +
                    " (keyframe id mismatch: wait for or request a keyframe)");
  }
  if (h.frame_index != ref_.frame_index + 1) {
    return NotFound(frame + " needs frame " + Str(h.frame_index - 1) + " as its reference, this decoder holds frame " +
                    Str(ref_.frame_index) + " (frame counter mismatch: a frame was lost)");
  }
  if (h.num_vertices != ref_.pos.size()) {
    return NotFound(frame + " has " + Str(h.num_vertices) + " vertices, the reference " + Str(ref_.pos.size()) +
                    " (vertex count mismatch)");
  }
  if (hash != ref_.hash) {
    return NotFound(frame + ": reference hash " + Str(hash) + " differs from this decoder's " + Str(ref_.hash) +
                    " (the reference positions differ)");
  }
  EncoderScratch& sc = Scratch();
  TokenReader tr;
  HOLO_RETURN_IF_ERROR(tr.Init(blob.subspan(r.position()), kContexts, "g2.displacements"));
  const size_t nv = ref_.pos.size();
  const auto ncomp = static_cast<uint32_t>(ref_.comp_start.size() - 1);
  if (nv + ncomp > tr.MaxSymbols()) {
    return DataLoss("g2.displacements: " + Str(nv + ncomp) + " values cannot fit in " + Str(blob.size() - r.position()) +
                    " bytes");
  }
  sc.motions.clear();
  {
    RigidMotion last;
    for (uint32_t c = 0; c < ncomp && tr.ok(); ++c) {
      const uint32_t moved = tr.GetValue(8);
      if (moved > 1) return DataLoss("g2.motion: cluster " + Str(c) + " has flag " + Str(moved));
      if (!moved) continue;
      RigidMotion m;
      m.component = c;
      int64_t q2 = 0;
      for (int k = 0; k < 3; ++k) {
        const int64_t t = int64_t{last.t[k]} + UnZigZag(tr.GetValue(9 + k));
        if (t < -kMaxTrans || t > kMaxTrans) return DataLoss("g2.motion: cluster " + Str(c) + " translation out of range");
        m.t[k] = static_cast<int32_t>(t);
      }
      for (int k = 0; k < 3; ++k) {
        const int64_t q = int64_t{last.q[k]} + UnZigZag(tr.GetValue(12 + k));
        if (q < -kRotScale || q > kRotScale) return DataLoss("g2.motion: cluster " + Str(c) + " rotation out of range");
        m.q[k] = static_cast<int32_t>(q);
        q2 += q * q;
      }
      if (q2 > int64_t{kRotScale} * kRotScale) return DataLoss("g2.motion: cluster " + Str(c) + " rotation is not a unit quaternion");
      sc.motions.push_back(m);
      last = m;
    }
  }
  sc.k.assign(nv, 0);
  sc.absres.assign(nv, 0);
  for (uint32_t v = 0; v < nv; ++v) {
    int32_t pred = 0;
    uint32_t ctx = 0;
    Predict(ref_, sc.k.data(), sc.absres.data(), v, &pred, &ctx);
    const uint32_t z = tr.GetValue(ctx);
    if (!tr.ok()) break;
    const int64_t k = int64_t{pred} + UnZigZag(z);
    if (k < -kMaxSteps || k > kMaxSteps) {
      return DataLoss("g2.displacements: vertex " + Str(v) + " moves more than " + Str(kMaxSteps) + " steps");
    }
    sc.k[v] = static_cast<int32_t>(k);
    sc.absres[v] = static_cast<int32_t>(std::abs(k - pred));
  }
  HOLO_RETURN_IF_ERROR(tr.Finish());
  sc.pos = ref_.pos;
  for (const RigidMotion& m : sc.motions) ApplyRigid(ref_, m, &sc.pos);
  if (!sc.motions.empty()) {
    ComputeNormals(sc.pos, ref_.triangles, &sc.rigid_normals);
    ApplyDisplacements(sc.rigid_normals, sc.k, step_units, &sc.pos);
  } else {
    ApplyDisplacements(ref_.normals, sc.k, step_units, &sc.pos);
  }
  ref_.pos.swap(sc.pos);
  ComputeNormals(ref_.pos, ref_.triangles, &ref_.normals);
  ref_.hash = HashPositions(ref_.pos);
  ++ref_.frame_index;
  ref_.ToMesh(mesh);
  return OkStatus();
}

}  // namespace holo::protocol
