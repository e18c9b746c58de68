#include "common/marching_cubes_table.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>
#include <vector>

#include <Eigen/Geometry>

#include "common/status.h"
#include "server/fusion/tsdf_internal.h"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace holo {

// ---------------------------------------------------------------------------
// Meshing of a TsdfVolume.

namespace {

// A block's voxels plus a one-voxel (low side) and two-voxel (high side)
// apron from its neighbours: voxel coordinates −1..9 on each axis. Cubes
// with origins −1..7 and gradients at voxels 0..8 can be read from it.
constexpr int kCacheSide = kBlockSide + 3;
constexpr int kCacheVoxels = kCacheSide * kCacheSide * kCacheSide;

inline int CacheIndex(int x, int y, int z) { return (x + 1) + kCacheSide * ((y + 1) + kCacheSide * (z + 1)); }
inline int NeighbourIndex(int dx, int dy, int dz) { return (dx + 1) + 3 * (dy + 1) + 9 * (dz + 1); }

// Per cache row (y, z ∈ −1..9), bit x + 1 for x ∈ −1..9.
constexpr int kCacheRows = kCacheSide * kCacheSide;
inline int RowIndex(int y, int z) { return (y + 1) + kCacheSide * (z + 1); }

struct BlockCache {
  float tsdf[kCacheVoxels];
  uint16_t ok[kCacheRows];    // voxel usable as a cube corner
  uint16_t neg[kCacheRows];   // tsdf < 0
  uint16_t seen[kCacheRows];  // weight > 0 (observed)
  uint16_t cube[kCacheRows];  // cube with origin (x, y, z) has all eight corners usable (y, z ∈ −1..7, x ∈ −1..7)
};

// Packs a reference to edge `edge` (voxel·3 + axis) of block `block`.
constexpr int kEdgeBits = 11;
static_assert(kEdgesPerBlock <= (1 << kEdgeBits));
inline uint32_t PackEdgeRef(int32_t block, int edge) {
  return (static_cast<uint32_t>(block) << kEdgeBits) | static_cast<uint32_t>(edge);
}

// Per voxel row (j + 8·k) of one block, bit i: usable as a cube corner
// (weight ≥ min_weight and, with skip_truncated_cubes, tsdf < 0.999),
// negative, observed (weight > 0). Computed once per block per
// ExtractMesh, then assembled into the 11-bit cache rows of every block that
// has it as a neighbour.
void ComputeRowMasks(const VoxelBlock& vb, float min_weight, float max_tsdf, TsdfVolume::RowMasks* m) {
#if defined(__SSE2__)
  const __m128 min_w = _mm_set1_ps(min_weight), max_t = _mm_set1_ps(max_tsdf), zero = _mm_setzero_ps();
  for (int r = 0; r < kBlockSide * kBlockSide; ++r) {
    const float* t = vb.tsdf + kBlockSide * r;
    const float* w = vb.weight + kBlockSide * r;
    const __m128 t0 = _mm_load_ps(t), t1 = _mm_load_ps(t + 4), w0 = _mm_load_ps(w), w1 = _mm_load_ps(w + 4);
    auto bits = [](__m128 lo, __m128 hi) { return static_cast<uint8_t>(_mm_movemask_ps(lo) | _mm_movemask_ps(hi) << 4); };
    m->bits[TsdfVolume::RowMasks::kOk][r] = bits(_mm_and_ps(_mm_cmpge_ps(w0, min_w), _mm_cmplt_ps(t0, max_t)),
                    _mm_and_ps(_mm_cmpge_ps(w1, min_w), _mm_cmplt_ps(t1, max_t)));
    m->bits[TsdfVolume::RowMasks::kNeg][r] = bits(_mm_cmplt_ps(t0, zero), _mm_cmplt_ps(t1, zero));
    m->bits[TsdfVolume::RowMasks::kSeen][r] = bits(_mm_cmpgt_ps(w0, zero), _mm_cmpgt_ps(w1, zero));
  }
#else
  for (int r = 0; r < kBlockSide * kBlockSide; ++r) {
    unsigned ok = 0, neg = 0, seen = 0;
    for (int x = 0; x < kBlockSide; ++x) {
      const float t = vb.tsdf[kBlockSide * r + x], w = vb.weight[kBlockSide * r + x];
      ok |= static_cast<unsigned>(w >= min_weight && t < max_tsdf) << x;
      neg |= static_cast<unsigned>(t < 0.0f) << x;
      seen |= static_cast<unsigned>(w > 0.0f) << x;
    }
    m->bits[TsdfVolume::RowMasks::kOk][r] = static_cast<uint8_t>(ok);
    m->bits[TsdfVolume::RowMasks::kNeg][r] = static_cast<uint8_t>(neg);
    m->bits[TsdfVolume::RowMasks::kSeen][r] = static_cast<uint8_t>(seen);
  }
#endif
}

void FillCache(const VoxelBlockMap& map, const TsdfVolume::RowMasks* masks, const int32_t nbr[27], BlockCache* c) {
  // Per axis, the three ranges of cache coordinates and where they come from:
  // cache coords [from, to], neighbour offset, local coordinate of `from`.
  struct Span {
    int from, to, block, local0;
  };
  static constexpr Span kSpans[3] = {{-1, -1, -1, kBlockSide - 1}, {0, kBlockSide - 1, 0, 0}, {kBlockSide, kBlockSide + 1, 1, 0}};
  // Missing neighbours read as an all-zero block (tsdf 0, never observed).
  static const VoxelBlock kZeroBlock{};
  static constexpr TsdfVolume::RowMasks kNone{};
  const float* tsdf[27];
  const TsdfVolume::RowMasks* row_masks[27];
  for (int i = 0; i < 27; ++i) {
    tsdf[i] = nbr[i] >= 0 ? map.block(nbr[i]).tsdf : kZeroBlock.tsdf;
    row_masks[i] = nbr[i] >= 0 ? &masks[nbr[i]] : &kNone;
  }
  for (const Span& sz : kSpans) {
    for (const Span& sy : kSpans) {
      // The three blocks along x of this (y, z) span.
      const int lo = NeighbourIndex(-1, sy.block, sz.block), mid = NeighbourIndex(0, sy.block, sz.block),
                hi = NeighbourIndex(1, sy.block, sz.block);
      const float *t_lo = tsdf[lo], *t_mid = tsdf[mid], *t_hi = tsdf[hi];
      const TsdfVolume::RowMasks &m_lo = *row_masks[lo], &m_mid = *row_masks[mid], &m_hi = *row_masks[hi];
      for (int z = sz.from; z <= sz.to; ++z) {
        const int lz = sz.local0 + (z - sz.from);
        for (int y = sy.from; y <= sy.to; ++y) {
          const int ly = sy.local0 + (y - sy.from);
          const int r8 = ly + kBlockSide * lz;
          const int row = kBlockSide * r8;
          float* dst = c->tsdf + CacheIndex(-1, y, z);
          dst[0] = t_lo[row + kBlockSide - 1];
          std::memcpy(dst + 1, t_mid + row, kBlockSide * sizeof(float));
          dst[kBlockSide + 1] = t_hi[row];
          dst[kBlockSide + 2] = t_hi[row + 1];
          // Bit x + 1 of the cache row = voxel x ∈ −1..9.
          auto assemble = [&](int kind) {
            return static_cast<uint16_t>((m_lo.bits[kind][r8] >> (kBlockSide - 1)) | m_mid.bits[kind][r8] << 1 |
                                         (m_hi.bits[kind][r8] & 3u) << (kBlockSide + 1));
          };
          const int r = RowIndex(y, z);
          c->ok[r] = assemble(TsdfVolume::RowMasks::kOk);
          c->neg[r] = assemble(TsdfVolume::RowMasks::kNeg);
          c->seen[r] = assemble(TsdfVolume::RowMasks::kSeen);
        }
      }
    }
  }
  // All eight corners usable, separably: pairs along x, then y and z.
  constexpr unsigned kCubeBits = (1u << (kBlockSide + 1)) - 1;  // origins x = −1..7
  for (int z = -1; z < kBlockSide; ++z)
    for (int y = -1; y < kBlockSide; ++y) {
      const unsigned a0 = c->ok[RowIndex(y, z)], a1 = c->ok[RowIndex(y + 1, z)];
      const unsigned a2 = c->ok[RowIndex(y, z + 1)], a3 = c->ok[RowIndex(y + 1, z + 1)];
      const unsigned all = a0 & a1 & a2 & a3;
      c->cube[RowIndex(y, z)] = static_cast<uint16_t>(all & (all >> 1) & kCubeBits);
    }
}


// TSDF gradient at cache voxel (x, y, z) ∈ [0, 8]³: central differences,
// one-sided next to unobserved voxels.
inline Eigen::Vector3f Gradient(const BlockCache& c, int x, int y, int z) {
  const int i = CacheIndex(x, y, z);
  static constexpr int kStride[3] = {1, kCacheSide, kCacheSide * kCacheSide};
  const float t0 = c.tsdf[i];
  const unsigned row = c.seen[RowIndex(y, z)];
  // Observed flags of the +/− neighbour on each axis.
  const bool p[3] = {((row >> (x + 2)) & 1) != 0, ((c.seen[RowIndex(y + 1, z)] >> (x + 1)) & 1) != 0,
                     ((c.seen[RowIndex(y, z + 1)] >> (x + 1)) & 1) != 0};
  const bool m[3] = {((row >> x) & 1) != 0, ((c.seen[RowIndex(y - 1, z)] >> (x + 1)) & 1) != 0,
                     ((c.seen[RowIndex(y, z - 1)] >> (x + 1)) & 1) != 0};
  Eigen::Vector3f g;
  for (int a = 0; a < 3; ++a) {
    const int ip = i + kStride[a], im = i - kStride[a];
    // Branch-free form of: both → ½(t+ − t−), one side → one-sided, none → 0.
    const float d = (p[a] ? c.tsdf[ip] : t0) - (m[a] ? c.tsdf[im] : t0);
    g[a] = p[a] && m[a] ? 0.5f * d : d;
  }
  return g;
}

// Smallest fraction of an edge between a vertex and the edge's end: keeps
// vertices of different edges apart when a corner value is exactly 0.
constexpr float kMinEdgeFraction = 1e-3f;

}  // namespace

void TsdfVolume::ExtractMesh(Mesh* out) const {
  out->positions.clear();
  out->normals.clear();
  out->colors.clear();
  out->triangles.clear();
  Scratch& s = *scratch_;
  const size_t nb = blocks_.size();
  stats_.mesh_blocks = 0;
  if (nb == 0) return;
  HOLO_CHECK_MSG(nb < (size_t{1} << (32 - kEdgeBits)), "too many voxel blocks for marching cubes");
  // Per cube edge: its (voxel·3 + axis) offset from the cube origin's, for
  // cubes whose edges all lie in the same block.
  int edge_offset[12];
  for (int e = 0; e < 12; ++e) {
    const int c = McEdgeLowCorner(e);
    edge_offset[e] = 3 * ((c & 1) + kBlockSide * (((c >> 1) & 1) + kBlockSide * ((c >> 2) & 1))) + McEdgeAxis(e);
  }
  const int threads = s.pool.num_threads();
  s.thread_vertices.resize(static_cast<size_t>(threads));
  s.thread_tris.resize(static_cast<size_t>(threads));
  for (auto& v : s.thread_vertices) v.clear();
  for (auto& t : s.thread_tris) t.clear();
  s.block_output.assign(nb, {});
  if (s.edge_vertex.size() < nb * kEdgesPerBlock) s.edge_vertex.resize(nb * kEdgesPerBlock);
  const float voxel = options_.voxel_size;
  const bool with_color = options_.integrate_color;
  // A usable cube needs a negative corner and a nonnegative one; with
  // skip_truncated_cubes the latter must lie inside the band (< 0.999).
  const uint8_t positive = options_.skip_truncated_cubes ? kBlockHasPositiveInBand : kBlockHasPositive;
  const uint8_t both = kBlockHasNegative | positive;
  std::vector<size_t> thread_mesh_blocks(static_cast<size_t>(threads), 0);

  // Pass 0 (per block, in parallel): row bit masks of every block.
  if (s.row_masks.size() < nb) s.row_masks.resize(nb);
  const float max_tsdf = options_.skip_truncated_cubes ? kTsdfBandLimit : 2.0f;  // 1 = beyond the band in every view
  const size_t num_tasks = (nb + 7) / 8;
  s.pool.Run(num_tasks, [&](size_t task, int) {
    const size_t end = std::min(nb, (task + 1) * 8);
    for (size_t bi = task * 8; bi < end; ++bi)
      ComputeRowMasks(blocks_.block(static_cast<int32_t>(bi)), options_.min_weight, max_tsdf, &s.row_masks[bi]);
  });

  // Pass 1 (per block, in parallel): vertices on the block's own edges
  // (edges starting at its voxels, along +x, +y, +z) and triangles of its own
  // cubes (origins at its voxels), the latter as (block, edge) references.
  s.pool.Run(num_tasks, [&](size_t task, int thread) {
    BlockCache cache;
    auto& verts = s.thread_vertices[static_cast<size_t>(thread)];
    auto& tris = s.thread_tris[static_cast<size_t>(thread)];
    const size_t end = std::min(nb, (task + 1) * 8);
    for (size_t bi = task * 8; bi < end; ++bi) {
      const int32_t b = static_cast<int32_t>(bi);
      const BlockCoord bc = blocks_.coord(b);
      int32_t nbr[27];
      // Cheap test first: a surface needs both signs among this block and its
      // +x/+y/+z neighbours (every owned edge and cube lies in them).
      uint8_t flags = 0;
      for (int dz = 0; dz <= 1; ++dz)
        for (int dy = 0; dy <= 1; ++dy)
          for (int dx = 0; dx <= 1; ++dx) {
            const int32_t n = (dx | dy | dz) ? blocks_.Find({bc.x + dx, bc.y + dy, bc.z + dz}) : b;
            nbr[NeighbourIndex(dx, dy, dz)] = n;
            if (n >= 0) flags |= blocks_.flags(n);
          }
      Scratch::BlockOutput& bo = s.block_output[bi];
      bo.thread = thread;
      bo.vertex_begin = static_cast<uint32_t>(verts.size());
      bo.tri_begin = static_cast<uint32_t>(tris.size());
      if ((flags & both) != both) continue;
      ++thread_mesh_blocks[static_cast<size_t>(thread)];
      for (int dz = -1; dz <= 1; ++dz)
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx)
            if (dx < 0 || dy < 0 || dz < 0) nbr[NeighbourIndex(dx, dy, dz)] = blocks_.Find({bc.x + dx, bc.y + dy, bc.z + dz});
      FillCache(blocks_, s.row_masks.data(), nbr, &cache);

      // Owned edges.
      uint16_t* edge_vertex = s.edge_vertex.data() + bi * kEdgesPerBlock;
      uint32_t local = 0;
      const Eigen::Vector3f block_origin = Eigen::Vector3f(static_cast<float>(bc.x), static_cast<float>(bc.y),
                                                           static_cast<float>(bc.z)) * static_cast<float>(kBlockSide);
      // Crossed edges that one of the four cubes around them needs, as bit
      // masks per row (bit x + 1 = voxel x), so only those are visited.
      constexpr unsigned kOwnBits = ((1u << kBlockSide) - 1) << 1;  // x = 0..7
      for (int z = 0; z < kBlockSide; ++z)
        for (int y = 0; y < kBlockSide; ++y) {
          const int r = RowIndex(y, z);
          const unsigned n0 = cache.neg[r];
          const unsigned cx = cache.cube[r] | cache.cube[RowIndex(y - 1, z)] | cache.cube[RowIndex(y, z - 1)] |
                              cache.cube[RowIndex(y - 1, z - 1)];
          const unsigned cy = cache.cube[r] | cache.cube[RowIndex(y, z - 1)];
          const unsigned cz = cache.cube[r] | cache.cube[RowIndex(y - 1, z)];
          unsigned edge_mask[3];
          edge_mask[0] = (n0 ^ (n0 >> 1)) & cx & kOwnBits;
          edge_mask[1] = (n0 ^ cache.neg[RowIndex(y + 1, z)]) & (cy | (cy << 1)) & kOwnBits;
          edge_mask[2] = (n0 ^ cache.neg[RowIndex(y, z + 1)]) & (cz | (cz << 1)) & kOwnBits;
          for (unsigned any = edge_mask[0] | edge_mask[1] | edge_mask[2]; any != 0; any &= any - 1) {
            const int x = std::countr_zero(any) - 1;
            const int ci = CacheIndex(x, y, z);
            const float t0 = cache.tsdf[ci];
            const int v = x + kBlockSide * (y + kBlockSide * z);
            for (int a = 0; a < 3; ++a) {
              if (!((edge_mask[a] >> (x + 1)) & 1)) continue;
              static constexpr int kStride[3] = {1, kCacheSide, kCacheSide * kCacheSide};
              const float t1 = cache.tsdf[ci + kStride[a]];
              const float f = std::clamp(t0 / (t0 - t1), kMinEdgeFraction, 1.0f - kMinEdgeFraction);
              Scratch::MeshVertex mv;
              Eigen::Vector3f pos(static_cast<float>(x), static_cast<float>(y), static_cast<float>(z));
              pos[a] += f;
              mv.position = (block_origin + pos) * voxel;
              int xyz1[3] = {x, y, z};
              ++xyz1[a];
              Eigen::Vector3f n = (1.0f - f) * Gradient(cache, x, y, z) + f * Gradient(cache, xyz1[0], xyz1[1], xyz1[2]);
              const float len = n.norm();
              mv.normal = len > 1e-12f ? Eigen::Vector3f(n / len) : Eigen::Vector3f::UnitZ();
              edge_vertex[3 * v + a] = static_cast<uint16_t>(local++);
              if (!with_color) {
                verts.push_back(mv);
                continue;
              }
              // Colour: the two end voxels (the second may be in a neighbour).
              const VoxelBlock& vb0 = blocks_.block(b);
              int32_t b1i = b;
              int v1 = v;
              if (xyz1[a] == kBlockSide) {
                int d[3] = {0, 0, 0};
                d[a] = 1;
                b1i = nbr[NeighbourIndex(d[0], d[1], d[2])];
                xyz1[a] = 0;
                v1 = xyz1[0] + kBlockSide * (xyz1[1] + kBlockSide * xyz1[2]);
              }
              const VoxelBlock& vb1 = blocks_.block(b1i);
              auto mix = [f](uint8_t c0, uint8_t c1) {
                return static_cast<uint8_t>((1.0f - f) * static_cast<float>(c0) + f * static_cast<float>(c1) + 0.5f);
              };
              mv.color = {mix(vb0.r[v], vb1.r[v1]), mix(vb0.g[v], vb1.g[v1]), mix(vb0.b[v], vb1.b[v1])};
              verts.push_back(mv);
            }
          }
        }
      bo.num_vertices = local;

      // Owned cubes: usable ones with corners of both signs.
      for (int z = 0; z < kBlockSide; ++z)
        for (int y = 0; y < kBlockSide; ++y) {
          const unsigned n0 = cache.neg[RowIndex(y, z)], n1 = cache.neg[RowIndex(y + 1, z)];
          const unsigned n2 = cache.neg[RowIndex(y, z + 1)], n3 = cache.neg[RowIndex(y + 1, z + 1)];
          const unsigned any = n0 | n1 | n2 | n3, all = n0 & n1 & n2 & n3;
          const unsigned mixed = (any | (any >> 1)) & ~(all & (all >> 1));
          for (unsigned m = cache.cube[RowIndex(y, z)] & mixed & kOwnBits; m != 0; m &= m - 1) {
            const int x = std::countr_zero(m) - 1;
            const int ci = CacheIndex(x, y, z);
            constexpr int sy = kCacheSide, sz = kCacheSide * kCacheSide;
            const int code = (cache.tsdf[ci] < 0) | (cache.tsdf[ci + 1] < 0) << 1 | (cache.tsdf[ci + sy] < 0) << 2 |
                             (cache.tsdf[ci + sy + 1] < 0) << 3 | (cache.tsdf[ci + sz] < 0) << 4 |
                             (cache.tsdf[ci + sz + 1] < 0) << 5 | (cache.tsdf[ci + sz + sy] < 0) << 6 |
                             (cache.tsdf[ci + sz + sy + 1] < 0) << 7;
            const McCase& mc = McTableCase(code);
            const int v0 = x + kBlockSide * (y + kBlockSide * z);
            if (x < kBlockSide - 1 && y < kBlockSide - 1 && z < kBlockSide - 1) {
              // Interior cube: every edge belongs to this block.
              for (int t = 0; t < mc.num_triangles; ++t) {
                const uint8_t* te = mc.edges + 3 * t;
                tris.push_back({PackEdgeRef(b, 3 * v0 + edge_offset[te[0]]), PackEdgeRef(b, 3 * v0 + edge_offset[te[1]]),
                                PackEdgeRef(b, 3 * v0 + edge_offset[te[2]])});
              }
              continue;
            }
            for (int t = 0; t < mc.num_triangles; ++t) {
              std::array<uint32_t, 3> ref;
              for (int k = 0; k < 3; ++k) {
                const int e = mc.edges[3 * t + k];
                const int c = McEdgeLowCorner(e);
                int p[3] = {x + (c & 1), y + ((c >> 1) & 1), z + ((c >> 2) & 1)};
                int d[3];
                for (int q = 0; q < 3; ++q) {
                  d[q] = p[q] >= kBlockSide;
                  p[q] -= d[q] * kBlockSide;
                }
                const int32_t owner = nbr[NeighbourIndex(d[0], d[1], d[2])];
                HOLO_CHECK(owner >= 0);
                ref[k] = PackEdgeRef(owner, 3 * (p[0] + kBlockSide * (p[1] + kBlockSide * p[2])) + McEdgeAxis(e));
              }
              tris.push_back(ref);
            }
          }
        }
      bo.num_tris = static_cast<uint32_t>(tris.size()) - bo.tri_begin;
    }
  });
  for (size_t t : thread_mesh_blocks) stats_.mesh_blocks += t;

  // Offsets in block order (deterministic for any thread count).
  uint32_t num_vertices = 0, num_tris = 0;
  for (Scratch::BlockOutput& bo : s.block_output) {
    bo.vertex_base = num_vertices;
    bo.tri_base = num_tris;
    num_vertices += bo.num_vertices;
    num_tris += bo.num_tris;
  }
  out->positions.resize(num_vertices);
  out->normals.resize(num_vertices);
  if (with_color) out->colors.resize(num_vertices);
  out->triangles.resize(num_tris);

  // Pass 2 (per block, in parallel): copy vertices.
  std::vector<uint8_t> thread_degenerate(static_cast<size_t>(threads), 0);
  s.pool.Run(num_tasks, [&](size_t task, int) {
    const size_t end = std::min(nb, (task + 1) * 8);
    for (size_t bi = task * 8; bi < end; ++bi) {
      const Scratch::BlockOutput& bo = s.block_output[bi];
      const auto& verts = s.thread_vertices[static_cast<size_t>(bo.thread)];
      for (uint32_t i = 0; i < bo.num_vertices; ++i) {
        const Scratch::MeshVertex& mv = verts[bo.vertex_begin + i];
        out->positions[bo.vertex_base + i] = mv.position;
        out->normals[bo.vertex_base + i] = mv.normal;
        if (with_color) out->colors[bo.vertex_base + i] = mv.color;
      }
    }
  });
  // Pass 3: resolve triangle references (after all vertices are in place: a
  // triangle may use vertices of a block another thread copies).
  s.pool.Run(num_tasks, [&](size_t task, int thread) {
    const size_t end = std::min(nb, (task + 1) * 8);
    for (size_t bi = task * 8; bi < end; ++bi) {
      const Scratch::BlockOutput& bo = s.block_output[bi];
      const auto& tris = s.thread_tris[static_cast<size_t>(bo.thread)];
      for (uint32_t i = 0; i < bo.num_tris; ++i) {
        const std::array<uint32_t, 3>& ref = tris[bo.tri_begin + i];
        std::array<uint32_t, 3>& tri = out->triangles[bo.tri_base + i];
        for (int k = 0; k < 3; ++k) {
          const uint32_t block = ref[k] >> kEdgeBits, edge = ref[k] & ((1u << kEdgeBits) - 1);
          tri[k] = s.block_output[block].vertex_base + s.edge_vertex[block * kEdgesPerBlock + edge];
        }
        const Eigen::Vector3f& p0 = out->positions[tri[0]];
        const Eigen::Vector3f& p1 = out->positions[tri[1]];
        const Eigen::Vector3f& p2 = out->positions[tri[2]];
        if ((p1 - p0).cross(p2 - p0).squaredNorm() <= 0.0f) {
          tri = {0, 0, 0};  // marked, removed below
          thread_degenerate[static_cast<size_t>(thread)] = 1;
        }
      }
    }
  });
  if (std::any_of(thread_degenerate.begin(), thread_degenerate.end(), [](uint8_t d) { return d != 0; })) {
    auto& t = out->triangles;
    t.erase(std::remove_if(t.begin(), t.end(), [](const std::array<uint32_t, 3>& tri) { return tri[0] == tri[1]; }),
            t.end());
  }
}

}  // namespace holo
