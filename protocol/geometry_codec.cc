#include "protocol/geometry_codec.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>

#include <lz4.h>
#include <meshoptimizer.h>
#include <zstd.h>

#include "protocol/byte_io.h"

namespace holo::protocol {
namespace {

constexpr uint8_t kHasNormals = 1u << 0;
constexpr uint8_t kHasColors = 1u << 1;
constexpr size_t kPrefixBytes = 12;

std::string Str(uint64_t v) { return std::to_string(v); }

void WritePrefix(ByteWriter& w, GeometryCodec codec, uint8_t flags, size_t nv, size_t nt) {
  w.U8(static_cast<uint8_t>(codec));
  w.U8(flags);
  w.U16(0);
  w.U32(static_cast<uint32_t>(nv));
  w.U32(static_cast<uint32_t>(nt));
}

// Welds vertices with bit-identical positions (marching cubes emits one copy
// per cell). `weld[i]` is the unique vertex of input vertex i; `unique` lists
// the first input vertex of every unique vertex.
void WeldExactPositions(const Mesh& mesh, std::vector<uint32_t>* weld, std::vector<uint32_t>* unique) {
  const size_t n = mesh.num_vertices();
  size_t cap = 16;
  while (cap < n * 2) cap <<= 1;
  std::vector<uint32_t> table(cap, UINT32_MAX);
  weld->resize(n);
  unique->clear();
  unique->reserve(n);
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector3f& p = mesh.positions[i];
    uint64_t h = std::bit_cast<uint32_t>(p.x());
    h = h * 0x9E3779B97F4A7C15ull ^ std::bit_cast<uint32_t>(p.y());
    h = h * 0x9E3779B97F4A7C15ull ^ std::bit_cast<uint32_t>(p.z());
    h *= 0xBF58476D1CE4E5B9ull;
    size_t slot = static_cast<size_t>(h >> 20) & (cap - 1);
    while (true) {
      const uint32_t u = table[slot];
      if (u == UINT32_MAX) {
        table[slot] = static_cast<uint32_t>(unique->size());
        (*weld)[i] = static_cast<uint32_t>(unique->size());
        unique->push_back(static_cast<uint32_t>(i));
        break;
      }
      const Eigen::Vector3f& q = mesh.positions[(*unique)[u]];
      if (std::memcmp(q.data(), p.data(), sizeof(float) * 3) == 0) {
        (*weld)[i] = u;
        break;
      }
      slot = (slot + 1) & (cap - 1);
    }
  }
}

Status CheckEncodable(const Mesh& mesh) {
  HOLO_RETURN_IF_ERROR(CheckMesh(mesh));
  const Limits limits;
  if (mesh.num_vertices() > limits.max_vertices) {
    return InvalidArgument("mesh has " + Str(mesh.num_vertices()) + " vertices, protocol limit " +
                           Str(limits.max_vertices));
  }
  if (mesh.num_triangles() > limits.max_triangles) {
    return InvalidArgument("mesh has " + Str(mesh.num_triangles()) + " triangles, protocol limit " +
                           Str(limits.max_triangles));
  }
  return OkStatus();
}

// ------------------------------------------------------------------ G0

Status EncodeG0(const Mesh& mesh, const GeometryEncodeOptions& o, std::vector<uint8_t>* out,
                std::vector<uint32_t>* vertex_map) {
  std::vector<uint32_t> weld, unique;
  WeldExactPositions(mesh, &weld, &unique);
  const bool normals = o.normals && !mesh.normals.empty();
  const bool colors = o.colors && !mesh.colors.empty();
  const size_t n = unique.size();
  ByteWriter w(out);
  out->reserve(out->size() + kPrefixBytes + n * (6 + 6 + 3) + mesh.num_triangles() * 12 / 2);
  WritePrefix(w, GeometryCodec::kG0, static_cast<uint8_t>((normals ? kHasNormals : 0) | (colors ? kHasColors : 0)), n,
              mesh.num_triangles());
  for (uint32_t i : unique)
    for (int c = 0; c < 3; ++c) w.U16(FloatToHalf(mesh.positions[i][c]));
  if (normals) {
    for (uint32_t i : unique)
      for (int c = 0; c < 3; ++c) w.U16(FloatToHalf(mesh.normals[i][c]));
  }
  if (colors) {
    for (uint32_t i : unique) w.Bytes(mesh.colors[i]);
  }
  std::vector<uint32_t> idx(mesh.num_triangles() * 3);
  for (size_t t = 0; t < mesh.num_triangles(); ++t)
    for (int c = 0; c < 3; ++c) idx[t * 3 + c] = weld[mesh.triangles[t][c]];
  const int src_bytes = static_cast<int>(idx.size() * 4);
  const size_t size_at = w.ReserveU32();
  if (src_bytes == 0) {  // no triangles: no index bytes at all
    if (vertex_map) *vertex_map = std::move(weld);
    return OkStatus();
  }
  const size_t start = out->size();
  out->resize(start + static_cast<size_t>(LZ4_compressBound(src_bytes)));
  const int lz = LZ4_compress_default(reinterpret_cast<const char*>(idx.data()),
                                      reinterpret_cast<char*>(out->data() + start), src_bytes,
                                      static_cast<int>(out->size() - start));
  if (lz <= 0) return Internal("LZ4 compression of the indices failed");
  out->resize(start + static_cast<size_t>(lz));
  w.PatchU32(size_at, static_cast<uint32_t>(lz));
  if (vertex_map) *vertex_map = std::move(weld);
  return OkStatus();
}

Status DecodeG0(ByteReader& r, uint8_t flags, uint32_t nv, uint32_t nt, Mesh* mesh) {
  const bool normals = flags & kHasNormals, colors = flags & kHasColors;
  const size_t per_vertex = 6 + (normals ? 6 : 0) + (colors ? 3 : 0);
  HOLO_RETURN_IF_ERROR(r.CheckCount("g0.num_vertices", nv, per_vertex));
  mesh->positions.resize(nv);
  for (auto& p : mesh->positions) {
    for (int c = 0; c < 3; ++c) {
      uint16_t h = 0;
      HOLO_RETURN_IF_ERROR(r.U16("g0.positions", &h));
      p[c] = HalfToFloat(h);
      if (!std::isfinite(p[c])) return DataLoss("g0.positions: not a finite number");
    }
  }
  if (normals) {
    mesh->normals.resize(nv);
    for (auto& p : mesh->normals) {
      for (int c = 0; c < 3; ++c) {
        uint16_t h = 0;
        HOLO_RETURN_IF_ERROR(r.U16("g0.normals", &h));
        p[c] = HalfToFloat(h);
        if (!std::isfinite(p[c])) return DataLoss("g0.normals: not a finite number");
      }
    }
  }
  if (colors) {
    mesh->colors.resize(nv);
    for (auto& c : mesh->colors) {
      std::span<const uint8_t> b;
      HOLO_RETURN_IF_ERROR(r.View("g0.colors", 3, &b));
      std::copy(b.begin(), b.end(), c.begin());
    }
  }
  std::span<const uint8_t> lz;
  HOLO_RETURN_IF_ERROR(r.Blob32("g0.indices", r.remaining(), &lz));
  HOLO_RETURN_IF_ERROR(r.ExpectEnd("g0"));
  // LZ4 expands at most ~255:1: a count beyond that cannot come from these bytes.
  if (uint64_t{nt} * 12 > uint64_t{lz.size()} * 255 + 16) {
    return DataLoss("g0.num_triangles: " + Str(nt) + " triangles cannot fit in " + Str(lz.size()) + " LZ4 bytes");
  }
  mesh->triangles.resize(nt);
  const int want = static_cast<int>(nt * 12);
  if (want > 0) {
    const int got = LZ4_decompress_safe(reinterpret_cast<const char*>(lz.data()),
                                        reinterpret_cast<char*>(mesh->triangles.data()), static_cast<int>(lz.size()),
                                        want);
    if (got != want) return DataLoss("g0.indices: LZ4 data is corrupt or has the wrong size");
  } else if (!lz.empty()) {
    return DataLoss("g0.indices: index bytes present for zero triangles");
  }
  for (const auto& t : mesh->triangles)
    for (uint32_t i : t)
      if (i >= nv) return DataLoss("g0.indices: vertex index " + Str(i) + " out of range (" + Str(nv) + " vertices)");
  return OkStatus();
}

// ------------------------------------------------------------------ G1

// Vertex → incident triangles (ascending triangle order), for finding the
// already-coded neighbour across an edge.
struct VertexTriangles {
  std::vector<uint32_t> offsets, tris;
  void Build(const std::vector<uint32_t>& idx, size_t nv) {
    offsets.assign(nv + 1, 0);
    for (uint32_t v : idx) ++offsets[v + 1];
    for (size_t i = 0; i < nv; ++i) offsets[i + 1] += offsets[i];
    tris.resize(idx.size());
    std::vector<uint32_t> fill(offsets.begin(), offsets.end() - 1);
    for (size_t k = 0; k < idx.size(); ++k) tris[fill[idx[k]]++] = static_cast<uint32_t>(k / 3);
  }
};

enum class Pred { kParallelogram, kAverage, kSingle, kPrevious };

// Walks the triangles in order and calls `visit(v, kind, a, b, d)` for every
// vertex at its first reference, in that order. The prediction of v is
// a + b - d (kParallelogram: the triangle across edge ab was coded before),
// (a + b) / 2 (kAverage), a (kSingle) or the previously visited vertex
// (kPrevious, a = that vertex or UINT32_MAX for the very first). Encoder and
// decoder run this same walk, so both see identical predictions. Returns the
// number of visited vertices.
template <typename Visit>
size_t WalkVertices(const std::vector<uint32_t>& idx, size_t nv, std::vector<uint8_t>* seen, Visit&& visit) {
  VertexTriangles vt;
  vt.Build(idx, nv);
  seen->assign(nv, 0);
  uint32_t prev = UINT32_MAX;
  size_t count = 0;
  const size_t nt = idx.size() / 3;
  for (size_t t = 0; t < nt; ++t) {
    const uint32_t* tri = &idx[t * 3];
    for (int i = 0; i < 3; ++i) {
      const uint32_t v = tri[i];
      if ((*seen)[v]) continue;
      const uint32_t a = tri[(i + 1) % 3], b = tri[(i + 2) % 3];
      const bool ka = (*seen)[a] && a != v, kb = (*seen)[b] && b != v;
      if (ka && kb) {
        // Triangle (v, a, b) is counter-clockwise; its neighbour across ab holds the directed edge b→a.
        uint32_t d = UINT32_MAX;
        for (uint32_t k = vt.offsets[b]; k < vt.offsets[b + 1]; ++k) {
          const uint32_t s = vt.tris[k];
          if (s >= t) break;
          const uint32_t* o = &idx[size_t{s} * 3];
          for (int j = 0; j < 3; ++j) {
            if (o[j] == b && o[(j + 1) % 3] == a) {
              d = o[(j + 2) % 3];
              break;
            }
          }
          if (d != UINT32_MAX) break;
        }
        if (d != UINT32_MAX) {
          visit(v, Pred::kParallelogram, a, b, d);
        } else {
          visit(v, Pred::kAverage, a, b, UINT32_MAX);
        }
      } else if (ka || kb) {
        visit(v, Pred::kSingle, ka ? a : b, UINT32_MAX, UINT32_MAX);
      } else {
        visit(v, Pred::kPrevious, prev, UINT32_MAX, UINT32_MAX);
      }
      (*seen)[v] = 1;
      prev = v;
      ++count;
    }
  }
  return count;
}

inline uint16_t ZigZag16(uint16_t r) {
  const auto s = static_cast<int16_t>(r);
  return static_cast<uint16_t>((static_cast<uint16_t>(s) << 1) ^ static_cast<uint16_t>(s >> 15));
}
inline uint16_t UnZigZag16(uint16_t z) { return static_cast<uint16_t>((z >> 1) ^ (0u - (z & 1u))); }
inline uint8_t ZigZag8(uint8_t r) {
  const auto s = static_cast<int8_t>(r);
  return static_cast<uint8_t>((static_cast<uint8_t>(s) << 1) ^ static_cast<uint8_t>(s >> 7));
}
inline uint8_t UnZigZag8(uint8_t z) { return static_cast<uint8_t>((z >> 1) ^ (0u - (z & 1u))); }

// Prediction of component values (integers modulo 2^bits) for one vertex.
template <typename T, size_t C>
std::array<int32_t, C> Predict(const std::vector<std::array<T, C>>& vals, Pred kind, uint32_t a, uint32_t b,
                               uint32_t d, bool parallelogram) {
  std::array<int32_t, C> p{};
  for (size_t c = 0; c < C; ++c) {
    switch (kind) {
      case Pred::kParallelogram:
        if (parallelogram) {
          p[c] = int32_t{vals[a][c]} + int32_t{vals[b][c]} - int32_t{vals[d][c]};
          break;
        }
        [[fallthrough]];
      case Pred::kAverage: p[c] = (int32_t{vals[a][c]} + int32_t{vals[b][c]} + 1) >> 1; break;
      case Pred::kSingle: p[c] = vals[a][c]; break;
      case Pred::kPrevious: p[c] = a == UINT32_MAX ? 0 : int32_t{vals[a][c]}; break;
    }
  }
  return p;
}

Status ZstdAppend(ByteWriter& w, std::vector<uint8_t>* out, const std::vector<uint8_t>& src, int level) {
  const size_t at = w.ReserveU32();
  const size_t start = out->size();
  out->resize(start + ZSTD_compressBound(src.size()));
  const size_t z = ZSTD_compress(out->data() + start, out->size() - start, src.data(), src.size(), level);
  if (ZSTD_isError(z)) return Internal(std::string("zstd: ") + ZSTD_getErrorName(z));
  out->resize(start + z);
  w.PatchU32(at, static_cast<uint32_t>(z));
  return OkStatus();
}

// Reads a u32-length zstd frame that must decompress to exactly `expect` bytes.
Status ZstdRead(ByteReader& r, const char* field, size_t expect, std::vector<uint8_t>* dst) {
  std::span<const uint8_t> z;
  HOLO_RETURN_IF_ERROR(r.Blob32(field, r.remaining(), &z));
  const unsigned long long declared = ZSTD_getFrameContentSize(z.data(), z.size());
  if (declared == ZSTD_CONTENTSIZE_ERROR || declared == ZSTD_CONTENTSIZE_UNKNOWN || declared != expect) {
    return DataLoss(std::string(field) + ": zstd frame does not declare the expected " + Str(expect) + " bytes");
  }
  dst->resize(expect);
  const size_t got = ZSTD_decompress(dst->data(), dst->size(), z.data(), z.size());
  if (ZSTD_isError(got) || got != expect) return DataLoss(std::string(field) + ": zstd data is corrupt");
  return OkStatus();
}

Status EncodeG1(const Mesh& mesh, const GeometryEncodeOptions& o, std::vector<uint8_t>* out,
                std::vector<uint32_t>* vertex_map) {
  std::vector<uint32_t> weld, unique;
  WeldExactPositions(mesh, &weld, &unique);
  const bool normals = o.normals && !mesh.normals.empty();
  const bool colors = o.colors && !mesh.colors.empty();
  const size_t nt = mesh.num_triangles();
  std::vector<uint32_t> idx(nt * 3);
  for (size_t t = 0; t < nt; ++t)
    for (int c = 0; c < 3; ++c) idx[t * 3 + c] = weld[mesh.triangles[t][c]];
  const size_t nu = unique.size();

  // Bounding box and grid of the referenced vertices.
  Eigen::Vector3f lo = Eigen::Vector3f::Constant(std::numeric_limits<float>::max());
  Eigen::Vector3f hi = -lo;
  for (uint32_t i : idx) {
    lo = lo.cwiseMin(mesh.positions[unique[i]]);
    hi = hi.cwiseMax(mesh.positions[unique[i]]);
  }
  if (nt == 0) lo = hi = Eigen::Vector3f::Zero();
  const float step = o.position_step_m;
  const float extent = (hi - lo).maxCoeff();
  if (extent / step > 65535.0f) {
    return InvalidArgument("mesh extent " + std::to_string(extent) + " m needs a position step of at least " +
                           std::to_string(extent / 65535.0f) + " m");
  }

  // Triangle order for the index codec, then vertices renumbered by first use.
  if (o.optimize_order && nt > 0) meshopt_optimizeVertexCacheFifo(idx.data(), idx.data(), idx.size(), nu, 16);
  std::vector<uint32_t> remap(nu);
  const size_t nv = nt > 0 ? meshopt_optimizeVertexFetchRemap(remap.data(), idx.data(), idx.size(), nu) : 0;
  if (nt == 0) std::fill(remap.begin(), remap.end(), UINT32_MAX);
  for (uint32_t& i : idx) i = remap[i];

  ByteWriter w(out);
  WritePrefix(w, GeometryCodec::kG1, static_cast<uint8_t>((normals ? kHasNormals : 0) | (colors ? kHasColors : 0)),
              nv, nt);
  for (int c = 0; c < 3; ++c) w.F32(lo[c]);
  w.F32(step);

  // Connectivity. The codec may rotate triangles, so the walk below uses the decoded order.
  std::vector<uint8_t> ib(meshopt_encodeIndexBufferBound(idx.size(), nv));
  meshopt_encodeIndexVersion(1);
  const size_t ibn = meshopt_encodeIndexBuffer(ib.data(), ib.size(), idx.data(), idx.size());
  if (ibn == 0 && !idx.empty()) return Internal("meshoptimizer index encoding failed");
  ib.resize(ibn);
  HOLO_RETURN_IF_ERROR(ZstdAppend(w, out, ib, o.zstd_level));
  if (!idx.empty() && meshopt_decodeIndexBuffer(idx.data(), idx.size(), 4, ib.data(), ib.size()) != 0) {
    return Internal("meshoptimizer index round trip failed");
  }

  // Attributes in the new vertex order.
  std::vector<std::array<uint16_t, 3>> q(nv);
  std::vector<std::array<uint8_t, 2>> oct(normals ? nv : 0);
  std::vector<std::array<uint8_t, 3>> col(colors ? nv : 0);
  for (size_t u = 0; u < nu; ++u) {
    const uint32_t v = remap[u];
    if (v == UINT32_MAX) continue;
    const uint32_t src = unique[u];
    for (int c = 0; c < 3; ++c) {
      q[v][c] = static_cast<uint16_t>(std::lround((mesh.positions[src][c] - lo[c]) / step));
    }
    if (normals) {
      float a, b;
      OctEncode(mesh.normals[src], &a, &b);
      oct[v] = {static_cast<uint8_t>(std::lround((a * 0.5f + 0.5f) * 255.0f)),
                static_cast<uint8_t>(std::lround((b * 0.5f + 0.5f) * 255.0f))};
    }
    if (colors) col[v] = mesh.colors[src];
  }

  std::vector<uint8_t> pos_res(nv * 6), nrm_res(normals ? nv * 2 : 0), col_res(colors ? nv * 3 : 0);
  size_t k = 0;
  std::vector<uint8_t> seen;
  WalkVertices(idx, nv, &seen, [&](uint32_t v, Pred kind, uint32_t a, uint32_t b, uint32_t d) {
    const auto p = Predict(q, kind, a, b, d, true);
    for (int c = 0; c < 3; ++c) {
      const uint16_t z = ZigZag16(static_cast<uint16_t>(q[v][c] - p[c]));
      pos_res[k * 3 + c] = static_cast<uint8_t>(z & 0xFF);         // low-byte plane
      pos_res[nv * 3 + k * 3 + c] = static_cast<uint8_t>(z >> 8);  // high-byte plane
    }
    if (normals) {
      const auto pn = Predict(oct, kind, a, b, d, false);
      for (int c = 0; c < 2; ++c) nrm_res[k * 2 + c] = ZigZag8(static_cast<uint8_t>(oct[v][c] - pn[c]));
    }
    if (colors) {
      const auto pc = Predict(col, kind, a, b, d, false);
      for (int c = 0; c < 3; ++c) col_res[k * 3 + c] = ZigZag8(static_cast<uint8_t>(col[v][c] - pc[c]));
    }
    ++k;
  });
  HOLO_CHECK(k == nv);
  HOLO_RETURN_IF_ERROR(ZstdAppend(w, out, pos_res, o.zstd_level));
  if (normals) HOLO_RETURN_IF_ERROR(ZstdAppend(w, out, nrm_res, o.zstd_level));
  if (colors) HOLO_RETURN_IF_ERROR(ZstdAppend(w, out, col_res, o.zstd_level));

  if (vertex_map) {
    vertex_map->resize(mesh.num_vertices());
    for (size_t i = 0; i < mesh.num_vertices(); ++i) (*vertex_map)[i] = remap[weld[i]];
  }
  return OkStatus();
}

Status DecodeG1(ByteReader& r, uint8_t flags, uint32_t nv, uint32_t nt, Mesh* mesh) {
  const bool normals = flags & kHasNormals, colors = flags & kHasColors;
  float origin[3], step = 0;
  for (float& f : origin) HOLO_RETURN_IF_ERROR(r.F32("g1.origin", &f));
  HOLO_RETURN_IF_ERROR(r.F32("g1.step", &step));
  if (!(step >= 1e-5f && step <= 0.1f)) return DataLoss("g1.step: must be in [1e-5, 0.1] m");
  if (uint64_t{nv} > uint64_t{nt} * 3) {
    return DataLoss("g1.num_vertices: " + Str(nv) + " vertices cannot all be referenced by " + Str(nt) + " triangles");
  }
  // meshoptimizer's index codec spends at least one byte per triangle plus a
  // 17-byte header and table, and at most its documented bound.
  std::vector<uint8_t> ib;
  {
    std::span<const uint8_t> z;
    HOLO_RETURN_IF_ERROR(r.Blob32("g1.indices", r.remaining(), &z));
    const unsigned long long declared = ZSTD_getFrameContentSize(z.data(), z.size());
    const uint64_t most = meshopt_encodeIndexBufferBound(size_t{nt} * 3, nv);
    const uint64_t least = nt > 0 ? uint64_t{nt} + 17 : 0;
    if (declared == ZSTD_CONTENTSIZE_ERROR || declared == ZSTD_CONTENTSIZE_UNKNOWN || declared < least ||
        declared > most) {
      return DataLoss("g1.indices: index stream size does not fit " + Str(nt) + " triangles");
    }
    ib.resize(declared);
    const size_t got = ZSTD_decompress(ib.data(), ib.size(), z.data(), z.size());
    if (ZSTD_isError(got) || got != declared) return DataLoss("g1.indices: zstd data is corrupt");
  }
  std::vector<uint32_t> idx(size_t{nt} * 3);
  if (nt > 0 && meshopt_decodeIndexBuffer(idx.data(), idx.size(), 4, ib.data(), ib.size()) != 0) {
    return DataLoss("g1.indices: index stream is corrupt");
  }
  for (uint32_t i : idx)
    if (i >= nv) return DataLoss("g1.indices: vertex index " + Str(i) + " out of range (" + Str(nv) + " vertices)");

  std::vector<uint8_t> pos_res, nrm_res, col_res;
  HOLO_RETURN_IF_ERROR(ZstdRead(r, "g1.positions", size_t{nv} * 6, &pos_res));
  if (normals) HOLO_RETURN_IF_ERROR(ZstdRead(r, "g1.normals", size_t{nv} * 2, &nrm_res));
  if (colors) HOLO_RETURN_IF_ERROR(ZstdRead(r, "g1.colors", size_t{nv} * 3, &col_res));
  HOLO_RETURN_IF_ERROR(r.ExpectEnd("g1"));

  std::vector<std::array<uint16_t, 3>> q(nv);
  std::vector<std::array<uint8_t, 2>> oct(normals ? nv : 0);
  std::vector<std::array<uint8_t, 3>> col(colors ? nv : 0);
  size_t k = 0;
  std::vector<uint8_t> seen;
  const size_t visited = WalkVertices(idx, nv, &seen, [&](uint32_t v, Pred kind, uint32_t a, uint32_t b, uint32_t d) {
    const auto p = Predict(q, kind, a, b, d, true);
    for (int c = 0; c < 3; ++c) {
      const uint16_t z = static_cast<uint16_t>(pos_res[k * 3 + c] | (pos_res[size_t{nv} * 3 + k * 3 + c] << 8));
      q[v][c] = static_cast<uint16_t>(p[c] + UnZigZag16(z));
    }
    if (normals) {
      const auto pn = Predict(oct, kind, a, b, d, false);
      for (int c = 0; c < 2; ++c) oct[v][c] = static_cast<uint8_t>(pn[c] + UnZigZag8(nrm_res[k * 2 + c]));
    }
    if (colors) {
      const auto pc = Predict(col, kind, a, b, d, false);
      for (int c = 0; c < 3; ++c) col[v][c] = static_cast<uint8_t>(pc[c] + UnZigZag8(col_res[k * 3 + c]));
    }
    ++k;
  });
  if (visited != nv) {
    return DataLoss("g1.num_vertices: " + Str(nv) + " vertices but triangles reference only " + Str(visited));
  }
  mesh->positions.resize(nv);
  for (size_t v = 0; v < nv; ++v)
    for (int c = 0; c < 3; ++c) mesh->positions[v][c] = origin[c] + static_cast<float>(q[v][c]) * step;
  if (normals) {
    mesh->normals.resize(nv);
    for (size_t v = 0; v < nv; ++v) {
      mesh->normals[v] = OctDecode(oct[v][0] / 255.0f * 2.0f - 1.0f, oct[v][1] / 255.0f * 2.0f - 1.0f);
    }
  }
  if (colors) mesh->colors = std::move(col);
  mesh->triangles.resize(nt);
  if (nt > 0) std::memcpy(mesh->triangles.data(), idx.data(), idx.size() * 4);
  return OkStatus();
}

}  // namespace

Status GeometryEncodeOptions::Check() const {
  if (codec != GeometryCodec::kG0 && codec != GeometryCodec::kG1) return InvalidArgument("codec must be G0 or G1");
  if (!(position_step_m >= 1e-5f && position_step_m <= 0.1f)) {
    return InvalidArgument("position_step_m must be in [1e-5, 0.1], got " + std::to_string(position_step_m));
  }
  if (zstd_level < 1 || zstd_level > 19) {
    return InvalidArgument("zstd_level must be in [1, 19], got " + std::to_string(zstd_level));
  }
  return OkStatus();
}

Status CheckMesh(const Mesh& mesh) {
  const size_t n = mesh.positions.size();
  if (!mesh.normals.empty() && mesh.normals.size() != n) {
    return DataLoss("mesh has " + Str(mesh.normals.size()) + " normals for " + Str(n) + " vertices");
  }
  if (!mesh.colors.empty() && mesh.colors.size() != n) {
    return DataLoss("mesh has " + Str(mesh.colors.size()) + " colors for " + Str(n) + " vertices");
  }
  for (size_t i = 0; i < n; ++i)
    if (!mesh.positions[i].allFinite()) return DataLoss("vertex " + Str(i) + " is not finite");
  for (size_t i = 0; i < mesh.normals.size(); ++i)
    if (!mesh.normals[i].allFinite()) return DataLoss("normal " + Str(i) + " is not finite");
  for (size_t t = 0; t < mesh.triangles.size(); ++t)
    for (uint32_t i : mesh.triangles[t])
      if (i >= n) return DataLoss("triangle " + Str(t) + " references vertex " + Str(i) + " of " + Str(n));
  return OkStatus();
}

void ClearMesh(Mesh* mesh) {
  mesh->positions.clear();
  mesh->normals.clear();
  mesh->colors.clear();
  mesh->triangles.clear();
}

void OctEncode(const Eigen::Vector3f& n, float* u, float* v) {
  const float s = std::abs(n.x()) + std::abs(n.y()) + std::abs(n.z());
  if (!(s > 0)) {
    *u = 0;
    *v = 0;
    return;
  }
  float x = n.x() / s, y = n.y() / s;
  if (n.z() < 0) {
    const float ox = x, oy = y;
    x = (1.0f - std::abs(oy)) * (ox >= 0 ? 1.0f : -1.0f);
    y = (1.0f - std::abs(ox)) * (oy >= 0 ? 1.0f : -1.0f);
  }
  *u = std::clamp(x, -1.0f, 1.0f);
  *v = std::clamp(y, -1.0f, 1.0f);
}

Eigen::Vector3f OctDecode(float u, float v) {
  Eigen::Vector3f n(u, v, 1.0f - std::abs(u) - std::abs(v));
  if (n.z() < 0) {
    const float ox = n.x(), oy = n.y();
    n.x() = (1.0f - std::abs(oy)) * (ox >= 0 ? 1.0f : -1.0f);
    n.y() = (1.0f - std::abs(ox)) * (oy >= 0 ? 1.0f : -1.0f);
  }
  return n.normalized();
}

Status EncodeGeometry(const Mesh& mesh, const GeometryEncodeOptions& options, std::vector<uint8_t>* out,
                      std::vector<uint32_t>* vertex_map) {
  HOLO_RETURN_IF_ERROR(options.Check());
  HOLO_RETURN_IF_ERROR(CheckEncodable(mesh));
  if (options.codec == GeometryCodec::kG0) return EncodeG0(mesh, options, out, vertex_map);
  return EncodeG1(mesh, options, out, vertex_map);
}

StatusOr<GeometryCodec> PeekGeometryCodec(std::span<const uint8_t> blob) {
  if (blob.empty()) return DataLoss("geometry.codec: empty blob");
  if (blob[0] != 1 && blob[0] != 2) return DataLoss("geometry.codec: unknown geometry codec " + Str(blob[0]));
  return static_cast<GeometryCodec>(blob[0]);
}

Status DecodeGeometry(std::span<const uint8_t> blob, Mesh* mesh, const Limits& limits) {
  ClearMesh(mesh);
  ByteReader r(blob);
  uint8_t codec = 0, flags = 0;
  uint16_t reserved = 0;
  uint32_t nv = 0, nt = 0;
  HOLO_RETURN_IF_ERROR(r.U8("geometry.codec", &codec));
  HOLO_RETURN_IF_ERROR(r.U8("geometry.flags", &flags));
  HOLO_RETURN_IF_ERROR(r.U16("geometry.reserved", &reserved));
  HOLO_RETURN_IF_ERROR(r.U32("geometry.num_vertices", &nv));
  HOLO_RETURN_IF_ERROR(r.U32("geometry.num_triangles", &nt));
  if (flags & ~(kHasNormals | kHasColors)) return DataLoss("geometry.flags: unknown flag bits set");
  if (reserved != 0) return DataLoss("geometry.reserved: must be zero");
  if (nv > limits.max_vertices) {
    return DataLoss("geometry.num_vertices: " + Str(nv) + " exceeds limit " + Str(limits.max_vertices));
  }
  if (nt > limits.max_triangles) {
    return DataLoss("geometry.num_triangles: " + Str(nt) + " exceeds limit " + Str(limits.max_triangles));
  }
  Status s;
  if (codec == static_cast<uint8_t>(GeometryCodec::kG0)) {
    s = DecodeG0(r, flags, nv, nt, mesh);
  } else if (codec == static_cast<uint8_t>(GeometryCodec::kG1)) {
    s = DecodeG1(r, flags, nv, nt, mesh);
  } else {
    s = DataLoss("geometry.codec: unknown geometry codec " + Str(codec));
  }
  if (!s.ok()) {
    ClearMesh(mesh);
    return s;
  }
  return OkStatus();
}

}  // namespace holo::protocol
