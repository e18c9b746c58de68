#include "protocol/surface_codec.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>
#include <string>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "common/marching_cubes_table.h"
#include "protocol/byte_io.h"
#include "protocol/geometry_codec.h"
#include "protocol/rans_coder.h"

namespace holo::protocol {
namespace {

using rans::TokenReader;
using rans::TokenWriter;

constexpr int kBrick = 4;  // samples per brick side (Field::At's shifts and masks assume 4)
constexpr int kBrickSamples = kBrick * kBrick * kBrick;
constexpr uint32_t kBrickContexts = 8;
constexpr uint32_t kLabelContexts = 81;
constexpr uint32_t kCrossingContexts = 16;  // by the edge's levels (1..15, 16+)
constexpr int kMinLevels = 2, kMaxLevels = 255;

constexpr uint8_t kNone = 0, kOutside = 1, kInside = 2;  // labels

int CeilDiv(int a, int b) { return (a + b - 1) / b; }

// The labelled part of a grid, stored per occupied brick: what the encoder
// sends and the decoder rebuilds. `cross` holds, per sample and axis, the
// level k ∈ [0, L) of the surface crossing on the edge to the next sample
// along that axis, where that edge is crossed.
struct Field {
  int nx = 0, ny = 0, nz = 0, bx = 0, by = 0, bz = 0;
  std::vector<int32_t> brick_slot;  // per brick, -1 = empty
  std::vector<int32_t> slot_brick;  // per slot, its brick (raster order)
  // Labels, dense with a margin of two samples on every side (0 there), so
  // that neighbourhoods need no bounds checks.
  std::vector<uint8_t> lab;
  size_t px = 0, pxy = 0;           // strides of `lab`
  // Per slot × 64 × 3, valid on crossed edges only (set where the crossing
  // is coded; the arrays keep their size between frames and are not
  // cleared: a slot's entries are written before they are read).
  std::vector<int16_t> cross;
  std::vector<uint8_t> cross_levels;  // the edge's levels
  mutable std::vector<uint32_t> vid;  // the edge's vertex (marching cubes), UINT32_MAX until made
  // Per row of bricks (iy, iz): its occupied bricks' ix, in
  // row_bricks[row_start[r], row_start[r + 1]) (IndexRows, once the slots are given).
  std::vector<uint32_t> row_start;
  std::vector<uint16_t> row_bricks;

  void Reset(int x, int y, int z) {
    nx = x;
    ny = y;
    nz = z;
    bx = CeilDiv(x, kBrick);
    by = CeilDiv(y, kBrick);
    bz = CeilDiv(z, kBrick);
    brick_slot.assign(static_cast<size_t>(bx) * static_cast<size_t>(by) * static_cast<size_t>(bz), -1);
    slot_brick.clear();
    px = static_cast<size_t>(x) + 4;
    pxy = px * (static_cast<size_t>(y) + 4);
    lab.assign(pxy * (static_cast<size_t>(z) + 4), kNone);
    // No occupied brick until IndexRows: ForEachSample visits nothing.
    row_start.assign(static_cast<size_t>(by) * static_cast<size_t>(bz) + 1, 0);
    row_bricks.clear();
  }
  int32_t AddSlot(size_t brick) {
    const auto s = static_cast<int32_t>(slot_brick.size());
    brick_slot[brick] = s;
    slot_brick.push_back(static_cast<int32_t>(brick));
    const size_t need = slot_brick.size() * 3 * kBrickSamples;
    if (cross.size() < need) {
      const size_t n = std::max<size_t>(need, 2 * cross.size());
      cross.resize(n);
      cross_levels.resize(n);
      vid.resize(n);
    }
    return s;
  }
  void IndexRows() {
    const size_t nrows = static_cast<size_t>(by) * static_cast<size_t>(bz);
    row_start.assign(nrows + 1, 0);
    row_bricks.clear();
    for (size_t r = 0; r < nrows; ++r) {
      row_start[r] = static_cast<uint32_t>(row_bricks.size());
      const int32_t* slot = &brick_slot[r * static_cast<size_t>(bx)];
      for (int b = 0; b < bx; ++b)
        if (slot[b] >= 0) row_bricks.push_back(static_cast<uint16_t>(b));
    }
    row_start[nrows] = static_cast<uint32_t>(row_bricks.size());
  }
  // Index into cross of sample (x, y, z) (× 3 + axis), or -1 outside the
  // grid or an empty brick.
  int64_t At(int x, int y, int z) const {
    if (x < 0 || y < 0 || z < 0 || x >= nx || y >= ny || z >= nz) return -1;
    const int32_t s = brick_slot[BrickOf(x, y, z)];
    if (s < 0) return -1;
    return int64_t{s} * kBrickSamples + (x & 3) + 4 * ((y & 3) + 4 * (z & 3));
  }
  // The brick of a sample inside the grid (shifts: coordinates are ≥ 0).
  size_t BrickOf(int x, int y, int z) const { return Brick(x >> 2, y >> 2, z >> 2); }
  size_t Brick(int ix, int iy, int iz) const {
    return static_cast<size_t>(ix) + static_cast<size_t>(bx) * (static_cast<size_t>(iy) + static_cast<size_t>(by) * static_cast<size_t>(iz));
  }
  // The brick coding's context: which of the −x, −y, −z neighbour bricks
  // are occupied (any slot value but −1: the decoder marks them −2 first).
  uint32_t BrickContext(int ix, int iy, int iz) const {
    auto occ = [&](int X, int Y, int Z) { return X >= 0 && Y >= 0 && Z >= 0 && brick_slot[Brick(X, Y, Z)] != -1; };
    return static_cast<uint32_t>(occ(ix - 1, iy, iz) + 2 * occ(ix, iy - 1, iz) + 4 * occ(ix, iy, iz - 1));
  }
  // Position of (x, y, z) in `lab`; x, y, z within [−2, n + 1].
  size_t P(int x, int y, int z) const {
    return static_cast<size_t>(x + 2) + px * static_cast<size_t>(y + 2) + pxy * static_cast<size_t>(z + 2);
  }
  uint8_t LabelAt(int x, int y, int z) const { return lab[P(x, y, z)]; }
};

int LabelContext(const Field& f, int x, int y, int z) {
  return f.LabelAt(x - 1, y, z) + 3 * f.LabelAt(x, y - 1, z) + 9 * f.LabelAt(x, y, z - 1) +
         27 * f.LabelAt(x + 1, y - 1, z);
}

// Calls fn(x, y, z, i) for every sample of an occupied brick inside the
// grid, in raster order (x fastest) over the whole grid; i = f.At(x, y, z).
template <typename Fn>
void ForEachSample(const Field& f, Fn&& fn) {
  for (int z = 0; z < f.nz; ++z)
    for (int y = 0; y < f.ny; ++y) {
      const size_t row = static_cast<size_t>(y >> 2) + static_cast<size_t>(f.by) * static_cast<size_t>(z >> 2);
      const size_t r1 = f.row_start[row + 1];
      if (f.row_start[row] == r1) continue;
      const int32_t* slot = &f.brick_slot[row * static_cast<size_t>(f.bx)];
      const size_t local = static_cast<size_t>(4 * ((y & 3) + 4 * (z & 3)));
      for (size_t r = f.row_start[row]; r < r1; ++r) {
        const int b = f.row_bricks[r];
        const size_t base = static_cast<size_t>(slot[b]) * kBrickSamples + local;
        const int x0 = b * kBrick, x1 = std::min(f.nx, x0 + kBrick);
        for (int x = x0; x < x1; ++x) fn(x, y, z, base + static_cast<size_t>(x - x0));
      }
    }
}

// Calls fn(x, y, z, axis, e) for every crossed edge (a labelled sample and
// the next one along `axis` labelled with the other sign), in the sample
// order, axes in turn; `e` indexes the edge in Field::cross.
template <typename Fn>
void ForEachCrossedEdge(const Field& f, Fn&& fn) {
  ForEachSample(f, [&](int x, int y, int z, size_t i) {
    const uint8_t lab = f.LabelAt(x, y, z);
    if (lab == kNone) return;
    for (int axis = 0; axis < 3; ++axis) {
      int p[3] = {x, y, z};
      ++p[axis];
      const uint8_t other = f.LabelAt(p[0], p[1], p[2]);
      if (other == kNone || other == lab) continue;
      const size_t e = 3 * i + static_cast<size_t>(axis);
      f.vid[e] = UINT32_MAX;  // MeshFromField makes its vertex
      fn(x, y, z, axis, e);
    }
  });
}

// Sums over a row of up to four labels d0..d3 (d3 = 0 for a row of three),
// indexed by 27·d0 + 9·d1 + 3·d2 + d3: the signs, and the signs weighted by
// 2·qx − mid for a row of four (−3, −1, 1, 3) and of three (−2, 0, 2).
struct RowSums {
  int8_t sum, moment4, moment3;
};
constexpr std::array<RowSums, 81> MakeRowSums() {
  std::array<RowSums, 81> t{};
  constexpr int kSign[3] = {0, 1, -1};
  for (int c = 0; c < 81; ++c) {
    const int d[4] = {c / 27, (c / 9) % 3, (c / 3) % 3, c % 3};
    int sum = 0, m4 = 0, m3 = 0;
    for (int k = 0; k < 4; ++k) {
      sum += kSign[d[k]];
      m4 += kSign[d[k]] * (2 * k - 3);
      m3 += kSign[d[k]] * (2 * k - 2);
    }
    t[static_cast<size_t>(c)] = {static_cast<int8_t>(sum), static_cast<int8_t>(m4), static_cast<int8_t>(m3)};
  }
  return t;
}
constexpr std::array<RowSums, 81> kRowSums = MakeRowSums();

// The row-sum index of the four labels at `p` (labels are 0..2): one
// 32-bit load (byte order spelled out; compilers fold it) and one multiply,
// the base-3 digits collecting in the top byte without carries (each lower
// byte of the product stays below 27).
inline uint32_t RowCode(const uint8_t* p, uint32_t keep) {
  const uint32_t u = uint32_t{p[0]} | uint32_t{p[1]} << 8 | uint32_t{p[2]} << 16 | uint32_t{p[3]} << 24;
  return ((u & keep) * 0x1B090301u) >> 24;
}

// Levels of the crossing on the edge from (x, y, z) along `axis`: L scaled
// by how squarely the surface meets the edge. The surface's normal is
// estimated from the labels alone (known to both sides before any crossing):
// g = Σ sign(q)·(q − m) over the labelled samples q of the 4×3×3 box around
// the edge (sign +1 outside, −1 inside; m the edge's middle; doubled
// coordinates keep it integer). With c² = g_axis² / |g|² (in 64ths), the
// edge gets max(1, round(L·c)) levels: a step of about voxel/L along the
// normal whatever the angle, and nothing spent on where a vertex slides
// within the surface along an edge that meets it at a grazing angle.
int EdgeLevels(const Field& f, int x, int y, int z, int axis, const uint8_t* level_of) {
  int lo[3] = {x - 1, y - 1, z - 1}, hi[3] = {x + 1, y + 1, z + 1};
  ++hi[axis];
  const int mid2[3] = {2 * x + (axis == 0), 2 * y + (axis == 1), 2 * z + (axis == 2)};
  // A row along x has four labels on an x edge, three on the others (the
  // fourth byte read, still inside the padded row, is masked off).
  const bool four = axis == 0;
  const uint32_t keep = four ? 0xFFFFFFFFu : 0x00FFFFFFu;
  int64_t g[3] = {0, 0, 0};
  for (int qz = lo[2]; qz <= hi[2]; ++qz)
    for (int qy = lo[1]; qy <= hi[1]; ++qy) {
      const RowSums& r = kRowSums[RowCode(&f.lab[f.P(x - 1, qy, qz)], keep)];
      g[0] += four ? r.moment4 : r.moment3;
      g[1] += r.sum * (2 * qy - mid2[1]);
      g[2] += r.sum * (2 * qz - mid2[2]);
    }
  const int64_t norm2 = g[0] * g[0] + g[1] * g[1] + g[2] * g[2];
  const int64_t c64 = norm2 > 0 ? (64 * g[axis] * g[axis]) / norm2 : 64;
  return level_of[c64];
}

// level_of[c64] = max(1, round(L·sqrt(c64 / 64))) for c64 ∈ [0, 64].
void LevelTable(int levels, uint8_t* level_of) {
  for (int c = 0; c <= 64; ++c)
    level_of[c] = static_cast<uint8_t>(std::max<long>(1, std::lround(levels * std::sqrt(c / 64.0))));
}

// Marching cubes over the cubes whose eight corners are labelled. Stops
// with DataLoss once the mesh would exceed `max_vertices` / `max_triangles`.
//
// With `counts` (the encoder, when no one wants the mesh): only the numbers
// of vertices and triangles, in counts[0] and counts[1]; `mesh` is unused.
Status MeshFromField(const Field& f, const Eigen::Vector3f& origin, float voxel, size_t max_vertices,
                     size_t max_triangles, Mesh* mesh, size_t* counts = nullptr) {
  size_t nv = 0, nt = 0;
  if (!counts) ClearMesh(mesh);
  // One vertex per crossed edge, made at its first use; `i` is the edge's
  // low sample, f.At(x, y, z).
  auto vertex = [&](int x, int y, int z, size_t i, int axis, uint32_t* id) -> bool {
    const size_t e = 3 * i + static_cast<size_t>(axis);
    if (f.vid[e] != UINT32_MAX) {
      *id = f.vid[e];
      return true;
    }
    if (nv >= max_vertices) return false;
    *id = f.vid[e] = static_cast<uint32_t>(nv++);
    if (counts) return true;
    const float t = (static_cast<float>(f.cross[e]) + 0.5f) / static_cast<float>(f.cross_levels[e]);
    Eigen::Vector3f p(static_cast<float>(x), static_cast<float>(y), static_cast<float>(z));
    p[axis] += t;
    mesh->positions.push_back(origin + voxel * p);
    return true;
  };
  // Offsets of a cube's corners in `lab`, and within a brick.
  size_t corner[8], in_brick[8];
  for (int c = 0; c < 8; ++c) {
    corner[c] = f.P(c & 1, (c >> 1) & 1, (c >> 2) & 1) - f.P(0, 0, 0);
    in_brick[c] = static_cast<size_t>((c & 1) + 4 * ((c >> 1) & 1) + 16 * (c >> 2));
  }
  int edge_low[12], edge_axis[12];
  for (int e = 0; e < 12; ++e) {
    edge_low[e] = McEdgeLowCorner(e);
    edge_axis[e] = McEdgeAxis(e);
  }
  bool overflow = false;
  ForEachSample(f, [&](int x, int y, int z, size_t i) {
    const size_t p0 = f.P(x, y, z);
    if (overflow || f.lab[p0] == kNone) return;
    int code = 0;
    for (int c = 0; c < 8; ++c) {
      const uint8_t lab = f.lab[p0 + corner[c]];
      if (lab == kNone) return;
      code |= (lab == kInside) << c;
    }
    if (code == 0 || code == 255) return;
    const McCase& mc = McTableCase(code);
    // A cube off its brick's far faces has all its corners in that brick.
    const bool one_brick = (x & 3) != 3 && (y & 3) != 3 && (z & 3) != 3;
    for (int t = 0; t < mc.num_triangles; ++t) {
      std::array<uint32_t, 3> tri{};
      for (int k = 0; k < 3; ++k) {
        const int e = mc.edges[3 * t + k];
        const int c = edge_low[e];
        const int X = x + (c & 1), Y = y + ((c >> 1) & 1), Z = z + ((c >> 2) & 1);
        const size_t ci = one_brick ? i + in_brick[c] : static_cast<size_t>(f.At(X, Y, Z));
        overflow |= !vertex(X, Y, Z, ci, edge_axis[e], &tri[static_cast<size_t>(k)]);
      }
      overflow |= nt >= max_triangles;
      if (overflow) return;
      ++nt;
      if (!counts) mesh->triangles.push_back(tri);
    }
  });
  if (overflow) return DataLoss("g3: the surface has more vertices or triangles than the prefix says");
  if (counts) {
    counts[0] = nv;
    counts[1] = nt;
    return OkStatus();
  }
  RecomputeNormals(mesh);
  return OkStatus();
}

struct G3Scratch {
  std::vector<uint8_t> bits;      // per sample: 1 observed, 2 negative
  std::vector<uint8_t> row_bits;  // per row of samples (y, z)
  std::vector<uint8_t> and4, or4; // per x of a cube row: the AND / OR of its four sample rows
  std::vector<int32_t> cube_id;   // per sample (cube origin): -1 or index into parent
  std::vector<int32_t> parent, size;
  std::vector<uint32_t> cubes;    // sample index of each surface cube
  std::vector<uint8_t> codes;     // its marching-cubes case
  Field field;
  std::vector<uint16_t> syms;
  std::vector<uint8_t> bricks_b, labels_b, crossings_b;
};
G3Scratch& G3ThreadScratch() {
  thread_local G3Scratch s;
  return s;
}

int32_t Find(std::vector<int32_t>& parent, int32_t i) {
  while (parent[static_cast<size_t>(i)] != i) {
    parent[static_cast<size_t>(i)] = parent[static_cast<size_t>(parent[static_cast<size_t>(i)])];
    i = parent[static_cast<size_t>(i)];
  }
  return i;
}


}  // namespace

Status SurfaceEncodeOptions::Check() const {
  if (!(position_step_m >= 1e-5f && position_step_m <= 0.1f))
    return InvalidArgument("g3 position_step_m must be in [1e-5, 0.1] m, got " + std::to_string(position_step_m));
  return OkStatus();
}

Status EncodeSurface(const SdfGrid& g, const SurfaceEncodeOptions& o, std::vector<uint8_t>* out, Mesh* decoded,
                     SurfaceEncodeStats* stats) {
  HOLO_RETURN_IF_ERROR(o.Check());
  if (g.nx < 1 || g.ny < 1 || g.nz < 1 || g.nx > kSurfaceMaxAxis || g.ny > kSurfaceMaxAxis || g.nz > kSurfaceMaxAxis)
    return InvalidArgument("g3: grid of " + Str(static_cast<uint64_t>(std::max(g.nx, 0))) + "×" +
                           Str(static_cast<uint64_t>(std::max(g.ny, 0))) + "×" + Str(static_cast<uint64_t>(std::max(g.nz, 0))) +
                           " samples: each axis must be in [1, " + Str(kSurfaceMaxAxis) + "]");
  if (g.sdf.size() != g.size())
    return InvalidArgument("g3: grid has " + Str(g.sdf.size()) + " values for " + Str(g.size()) + " samples");
  if (!(g.voxel_m >= 1e-4f && g.voxel_m <= 1.0f)) return InvalidArgument("g3: voxel must be in [1e-4, 1] m");
  if (o.position_step_m > 0.5f * g.voxel_m) return InvalidArgument("g3: the position step exceeds half the voxel");
  if (g.voxel_m / o.position_step_m > 255.5f)
    return InvalidArgument("g3: the position step is under 1/255 of the voxel");
  for (int a = 0; a < 3; ++a)
    if (!std::isfinite(g.origin[a]) || std::abs(g.origin[a]) > 1e6f) return InvalidArgument("g3: origin is not finite");
  SurfaceEncodeStats local;
  SurfaceEncodeStats& st = stats ? *stats : local;
  st = SurfaceEncodeStats{};
  G3Scratch& sc = G3ThreadScratch();
  const size_t n = g.size();
  const int nx = g.nx, ny = g.ny, nz = g.nz;
  const size_t sx = 1, sy = static_cast<size_t>(nx), sz = static_cast<size_t>(nx) * static_cast<size_t>(ny);
  sc.bits.resize(n);
  // Per row of samples: 1 some observed, 2 some behind the surface, 4 some in front.
  const size_t rows = static_cast<size_t>(ny) * static_cast<size_t>(nz);
  sc.row_bits.assign(rows, 0);
  for (size_t r = 0; r < rows; ++r) {
    // Branch-free: observed = (v == v), behind = v < 0.
    uint8_t rb = 0;
    const float* in = &g.sdf[r * sy];
    uint8_t* bits = &sc.bits[r * sy];
    size_t x = 0;
#if defined(__SSE2__)
    // Sixteen samples at a time (the scalar loop's results, byte for byte).
    {
      const __m128 zero = _mm_setzero_ps();
      const __m128i one = _mm_set1_epi32(1), two = _mm_set1_epi32(2), four = _mm_set1_epi32(4);
      __m128i any = _mm_setzero_si128();
      for (; x + 16 <= sy; x += 16) {
        __m128i b[4], f[4];
        for (int k = 0; k < 4; ++k) {
          const __m128 v = _mm_loadu_ps(in + x + 4 * k);
          const __m128i obs = _mm_castps_si128(_mm_cmpord_ps(v, v));
          const __m128i neg = _mm_castps_si128(_mm_cmplt_ps(v, zero));
          b[k] = _mm_or_si128(_mm_and_si128(obs, one), _mm_and_si128(neg, two));
          f[k] = _mm_and_si128(_mm_andnot_si128(neg, obs), four);
        }
        const __m128i bytes = _mm_packs_epi16(_mm_packs_epi32(b[0], b[1]), _mm_packs_epi32(b[2], b[3]));
        const __m128i front = _mm_packs_epi16(_mm_packs_epi32(f[0], f[1]), _mm_packs_epi32(f[2], f[3]));
        _mm_storeu_si128(reinterpret_cast<__m128i*>(bits + x), bytes);
        any = _mm_or_si128(any, _mm_or_si128(bytes, front));
      }
      any = _mm_or_si128(any, _mm_srli_si128(any, 8));
      any = _mm_or_si128(any, _mm_srli_si128(any, 4));
      any = _mm_or_si128(any, _mm_srli_si128(any, 2));
      any = _mm_or_si128(any, _mm_srli_si128(any, 1));
      rb = static_cast<uint8_t>(_mm_cvtsi128_si32(any));
    }
#endif
    for (; x < sy; ++x) {
      const float v = in[x];
      const uint8_t obs = v == v, neg = v < 0;
      const uint8_t b = static_cast<uint8_t>(obs | (neg << 1));
      bits[x] = b;
      rb |= static_cast<uint8_t>(b | ((obs & (neg ^ 1)) << 2));
    }
    sc.row_bits[r] = rb;
  }
  // Surface cubes: eight observed corners and a sign change. (cube_id is
  // all −1 between calls: only the entries set here are reset at the end.)
  if (sc.cube_id.size() < n) sc.cube_id.resize(n, -1);
  sc.cubes.clear();
  sc.and4.resize(static_cast<size_t>(nx));
  sc.or4.resize(static_cast<size_t>(nx));
  const size_t corner_off[8] = {0, sx, sy, sx + sy, sz, sx + sz, sy + sz, sx + sy + sz};
  for (int z = 0; z + 1 < nz; ++z)
    for (int y = 0; y + 1 < ny; ++y) {
      const size_t r = static_cast<size_t>(y) + static_cast<size_t>(ny) * static_cast<size_t>(z);
      const size_t rr[4] = {r, r + 1, r + static_cast<size_t>(ny), r + static_cast<size_t>(ny) + 1};
      uint8_t all = 1, any = 0;
      for (size_t q : rr) {
        all &= sc.row_bits[q];
        any |= sc.row_bits[q];
      }
      if (!all || (any & 6) != 6) continue;  // no cube of these rows can hold the surface
      // The four rows' AND and OR per x (vectorizable), then pairs of x.
      const size_t row = g.Index(0, y, z);
      const uint8_t* b0 = &sc.bits[row];
      const uint8_t *b1 = b0 + sy, *b2 = b0 + sz, *b3 = b0 + sy + sz;
      uint8_t* and4 = sc.and4.data();
      uint8_t* or4 = sc.or4.data();
      for (int x = 0; x < nx; ++x) {
        and4[x] = b0[x] & b1[x] & b2[x] & b3[x];
        or4[x] = b0[x] | b1[x] | b2[x] | b3[x];
      }
      int x = 0;
#if defined(__SSE2__)
      // Sixteen cubes at a time: a cube holds the surface where its corners
      // are all observed (bit 0 of all), not all behind (bit 1 of all
      // clear) and some behind (bit 1 of any).
      {
        const __m128i three = _mm_set1_epi8(3), one = _mm_set1_epi8(1), two = _mm_set1_epi8(2);
        for (; x + 17 <= nx; x += 16) {
          const __m128i a0 = _mm_loadu_si128(reinterpret_cast<const __m128i*>(and4 + x));
          const __m128i a1 = _mm_loadu_si128(reinterpret_cast<const __m128i*>(and4 + x + 1));
          const __m128i o0 = _mm_loadu_si128(reinterpret_cast<const __m128i*>(or4 + x));
          const __m128i o1 = _mm_loadu_si128(reinterpret_cast<const __m128i*>(or4 + x + 1));
          const __m128i all8 = _mm_and_si128(a0, a1), any8 = _mm_or_si128(o0, o1);
          const __m128i hit = _mm_and_si128(_mm_cmpeq_epi8(_mm_and_si128(all8, three), one),
                                            _mm_cmpeq_epi8(_mm_and_si128(any8, two), two));
          for (auto m = static_cast<uint32_t>(_mm_movemask_epi8(hit)); m; m &= m - 1) {
            const size_t i = row + static_cast<size_t>(x + std::countr_zero(m));
            sc.cube_id[i] = static_cast<int32_t>(sc.cubes.size());
            sc.cubes.push_back(static_cast<uint32_t>(i));
          }
        }
      }
#endif
      for (; x + 1 < nx; ++x) {
        const uint8_t all = and4[x] & and4[x + 1], any = or4[x] | or4[x + 1];
        if ((all & 1) && (any & 2) && !(all & 2)) {
          const size_t i = row + static_cast<size_t>(x);
          sc.cube_id[i] = static_cast<int32_t>(sc.cubes.size());
          sc.cubes.push_back(static_cast<uint32_t>(i));
        }
      }
    }
  st.surface_cubes = sc.cubes.size();
  st.grid_samples = n;
  // Pieces of surface: cubes joined to their −x, −y and −z neighbours when
  // the face they share has a sign change (their triangles then share a
  // vertex on it), sized in triangles, as the site's clean-up counts mesh
  // fragments.
  const size_t nc = sc.cubes.size();
  sc.parent.resize(nc);
  std::iota(sc.parent.begin(), sc.parent.end(), 0);
  sc.codes.resize(nc);
  // The corners of a cube's low x, y and z faces (case bits), and the step
  // to the neighbour across each.
  static constexpr int kFaceMask[3] = {0x55, 0x33, 0x0F};
  const size_t face_step[3] = {sx, sy, sz};
  for (size_t c = 0; c < nc; ++c) {
    const size_t i = sc.cubes[c];
    int code = 0;
    for (int k = 0; k < 8; ++k) code |= (sc.bits[i + corner_off[k]] & 2) ? 1 << k : 0;
    sc.codes[c] = static_cast<uint8_t>(code);
    for (int a = 0; a < 3; ++a) {
      const int face = code & kFaceMask[a];
      if (face == 0 || face == kFaceMask[a] || i < face_step[a]) continue;
      const int32_t j = sc.cube_id[i - face_step[a]];  // a wrapped x or y neighbour is never a cube with this face
      if (j < 0) continue;
      const int32_t ra = Find(sc.parent, static_cast<int32_t>(c)), rb = Find(sc.parent, j);
      if (ra != rb) sc.parent[static_cast<size_t>(std::max(ra, rb))] = std::min(ra, rb);
    }
  }
  sc.size.assign(nc, 0);
  for (size_t c = 0; c < nc; ++c)
    sc.size[static_cast<size_t>(Find(sc.parent, static_cast<int32_t>(c)))] += McTableCase(sc.codes[c]).num_triangles;
  // Cube c lies in a piece too small to keep.
  auto dropped = [&](size_t c) {
    return static_cast<size_t>(sc.size[static_cast<size_t>(Find(sc.parent, static_cast<int32_t>(c)))]) <
           o.min_component_triangles;
  };
  // A grid larger than the format allows (a site's box spans every piece
  // behind the surface, and a few far floaters of a fused volume can stretch
  // it to metres) is cut to the box of the cubes kept; the pieces dropped
  // stay dropped in the cut (a piece can only lose cubes there), so the blob
  // says the same surface. The cut costs a second pass over the smaller box.
  if (SurfacePaddedSamples(nx, ny, nz) > kSurfaceMaxSamples) {
    int lo[3] = {nx, ny, nz}, hi[3] = {-1, -1, -1};
    for (size_t c = 0; c < nc; ++c) {
      if (dropped(c)) continue;
      const size_t i = sc.cubes[c];
      const int p[3] = {static_cast<int>(i % sy), static_cast<int>((i / sy) % static_cast<size_t>(ny)),
                        static_cast<int>(i / sz)};
      for (int a = 0; a < 3; ++a) {
        lo[a] = std::min(lo[a], p[a]);
        hi[a] = std::max(hi[a], p[a] + 1);  // the cube's far corner
      }
    }
    for (uint32_t i : sc.cubes) sc.cube_id[i] = -1;
    const bool none = hi[0] < 0;  // nothing kept: a one-sample grid says so
    if (none) lo[0] = lo[1] = lo[2] = hi[0] = hi[1] = hi[2] = 0;
    const int cx = hi[0] - lo[0] + 1, cy = hi[1] - lo[1] + 1, cz = hi[2] - lo[2] + 1;
    if (SurfacePaddedSamples(cx, cy, cz) > kSurfaceMaxSamples)
      return OutOfRange("g3: grid of " + Str(static_cast<uint64_t>(nx)) + "×" + Str(static_cast<uint64_t>(ny)) +
                        "×" + Str(static_cast<uint64_t>(nz)) + " samples whose surface spans " +
                        Str(static_cast<uint64_t>(cx)) + "×" + Str(static_cast<uint64_t>(cy)) + "×" +
                        Str(static_cast<uint64_t>(cz)) + ": too large ((nx+4)(ny+4)(nz+4) must be ≤ " +
                        Str(kSurfaceMaxSamples) + ")");
    SdfGrid crop;
    crop.voxel_m = g.voxel_m;
    crop.nx = cx;
    crop.ny = cy;
    crop.nz = cz;
    crop.origin = g.origin + g.voxel_m * Eigen::Vector3f(static_cast<float>(lo[0]), static_cast<float>(lo[1]),
                                                         static_cast<float>(lo[2]));
    crop.sdf.assign(crop.size(), std::numeric_limits<float>::quiet_NaN());
    if (!none)
      for (int z = 0; z < cz; ++z)
        for (int y = 0; y < cy; ++y)
          std::copy_n(&g.sdf[g.Index(lo[0], lo[1] + y, lo[2] + z)], cx, &crop.sdf[crop.Index(0, y, z)]);
    return EncodeSurface(crop, o, out, decoded, stats);
  }
  // Labels: the corners of the kept cubes.
  Field& f = sc.field;
  f.Reset(nx, ny, nz);
  for (size_t c = 0; c < nc; ++c) {
    if (dropped(c)) {
      ++st.dropped_cubes;
      continue;
    }
    const size_t i = sc.cubes[c];
    const int x = static_cast<int>(i % sy), y = static_cast<int>((i / sy) % static_cast<size_t>(ny)), z = static_cast<int>(i / sz);
    for (int k = 0; k < 8; ++k) {
      const int X = x + (k & 1), Y = y + ((k >> 1) & 1), Z = z + ((k >> 2) & 1);
      f.lab[f.P(X, Y, Z)] = (sc.bits[g.Index(X, Y, Z)] & 2) ? kInside : kOutside;
      f.brick_slot[f.BrickOf(X, Y, Z)] = -2;  // occupied; slots are given in raster order below
    }
  }
  for (size_t b = 0; b < f.brick_slot.size(); ++b)
    if (f.brick_slot[b] == -2) f.AddSlot(b);
  f.IndexRows();
  st.occupied_bricks = f.slot_brick.size();
  if (st.occupied_bricks > kSurfaceMaxOccupiedBricks) {
    for (uint32_t i : sc.cubes) sc.cube_id[i] = -1;
    return OutOfRange("g3: the surface occupies " + Str(st.occupied_bricks) + " bricks of 4³ samples, more than " +
                      Str(kSurfaceMaxOccupiedBricks));
  }
  for (uint32_t i : sc.cubes) sc.cube_id[i] = -1;

  // Streams.
  const int levels = std::clamp(static_cast<int>(std::lround(g.voxel_m / o.position_step_m)), kMinLevels, kMaxLevels);
  TokenWriter bricks(kBrickContexts);
  for (int z = 0; z < f.bz; ++z)
    for (int y = 0; y < f.by; ++y)
      for (int x = 0; x < f.bx; ++x) bricks.Put(f.BrickContext(x, y, z), f.brick_slot[f.Brick(x, y, z)] >= 0 ? 1 : 0);
  TokenWriter labels(kLabelContexts, f.slot_brick.size() * kBrickSamples, &sc.syms);
  ForEachSample(f, [&](int x, int y, int z, size_t) {
    const uint8_t lab = f.LabelAt(x, y, z);
    labels.Put(static_cast<uint32_t>(LabelContext(f, x, y, z)), lab);
    st.labelled += lab != kNone;
  });
  TokenWriter crossings(kCrossingContexts);
  uint8_t level_of[65];
  LevelTable(levels, level_of);
  ForEachCrossedEdge(f, [&](int x, int y, int z, int axis, size_t e) {
    // The crossing of the input's linear interpolation, on the edge's levels.
    int p[3] = {x, y, z};
    ++p[axis];
    const double v0 = g.sdf[g.Index(x, y, z)], v1 = g.sdf[g.Index(p[0], p[1], p[2])];
    // In [0, 1] for finite samples of opposite signs; an infinite one gives
    // NaN (the edge's middle) or ±1, kept in range before the conversion to int.
    const double q = v0 / (v0 - v1);
    const double t = q == q ? std::clamp(q, 0.0, 1.0) : 0.5;
    const int le = EdgeLevels(f, x, y, z, axis, level_of);
    const int k = std::clamp(static_cast<int>(std::floor(t * le)), 0, le - 1);
    if (le > 1) crossings.PutValue(static_cast<uint32_t>(std::min(le, static_cast<int>(kCrossingContexts)) - 1), static_cast<uint32_t>(k));
    f.cross[e] = static_cast<int16_t>(k);
    f.cross_levels[e] = static_cast<uint8_t>(le);
    ++st.crossings;
  });
  sc.bricks_b.clear();
  sc.labels_b.clear();
  sc.crossings_b.clear();
  bricks.Finish(&sc.bricks_b);
  labels.Finish(&sc.labels_b);
  crossings.Finish(&sc.crossings_b);
  st.brick_bytes = sc.bricks_b.size();
  st.label_bytes = sc.labels_b.size();
  st.crossing_bytes = sc.crossings_b.size();

  const Limits limits;
  size_t counts[2] = {0, 0};
  HOLO_RETURN_IF_ERROR(MeshFromField(f, g.origin, g.voxel_m, limits.max_vertices, limits.max_triangles, decoded,
                                     decoded ? nullptr : counts)
                           .WithContext("g3 encoder: the surface exceeds the protocol limits"));
  st.vertices = decoded ? decoded->num_vertices() : counts[0];
  st.triangles = decoded ? decoded->num_triangles() : counts[1];

  ByteWriter w(out);
  w.U8(static_cast<uint8_t>(GeometryCodec::kG3));
  w.U8(0);
  w.U16(0);
  w.U32(static_cast<uint32_t>(st.vertices));
  w.U32(static_cast<uint32_t>(st.triangles));
  w.F32(g.origin.x());
  w.F32(g.origin.y());
  w.F32(g.origin.z());
  w.F32(g.voxel_m);
  w.U8(static_cast<uint8_t>(levels));
  w.U16(static_cast<uint16_t>(nx - 1));
  w.U16(static_cast<uint16_t>(ny - 1));
  w.U16(static_cast<uint16_t>(nz - 1));
  w.Blob32(sc.bricks_b);
  w.Blob32(sc.labels_b);
  w.Blob32(sc.crossings_b);
  return OkStatus();
}

namespace internal {

Status DecodeSurfaceBody(ByteReader& r, uint32_t nv, uint32_t nt, Mesh* mesh) {
  float origin[3], voxel = 0;
  uint8_t levels = 0;
  HOLO_RETURN_IF_ERROR(r.F32("g3.origin", &origin[0]));
  HOLO_RETURN_IF_ERROR(r.F32("g3.origin", &origin[1]));
  HOLO_RETURN_IF_ERROR(r.F32("g3.origin", &origin[2]));
  HOLO_RETURN_IF_ERROR(r.F32("g3.voxel", &voxel));
  HOLO_RETURN_IF_ERROR(r.U8("g3.levels", &levels));
  uint16_t dims[3];
  HOLO_RETURN_IF_ERROR(r.U16("g3.nx", &dims[0]));
  HOLO_RETURN_IF_ERROR(r.U16("g3.ny", &dims[1]));
  HOLO_RETURN_IF_ERROR(r.U16("g3.nz", &dims[2]));
  for (float v : origin)
    if (std::abs(v) > 1e6f) return DataLoss("g3.origin: not a finite coordinate");
  if (!(voxel >= 1e-4f && voxel <= 1.0f)) return DataLoss("g3.voxel: must be in [1e-4, 1] m");
  if (levels < kMinLevels) return DataLoss("g3.levels: must be in [2, 255]");
  const int nx = dims[0] + 1, ny = dims[1] + 1, nz = dims[2] + 1;
  if (nx > kSurfaceMaxAxis || ny > kSurfaceMaxAxis || nz > kSurfaceMaxAxis)
    return DataLoss("g3.nx/ny/nz: an axis exceeds " + Str(kSurfaceMaxAxis) + " samples");
  if (SurfacePaddedSamples(nx, ny, nz) > kSurfaceMaxSamples)
    return DataLoss("g3.nx/ny/nz: the grid is too large ((nx+4)(ny+4)(nz+4) must be ≤ " + Str(kSurfaceMaxSamples) + ")");
  std::span<const uint8_t> bricks_b, labels_b, crossings_b;
  HOLO_RETURN_IF_ERROR(r.Blob32("g3.bricks", r.remaining(), &bricks_b));
  HOLO_RETURN_IF_ERROR(r.Blob32("g3.labels", r.remaining(), &labels_b));
  HOLO_RETURN_IF_ERROR(r.Blob32("g3.crossings", r.remaining(), &crossings_b));
  HOLO_RETURN_IF_ERROR(r.ExpectEnd("g3"));
  if (uint64_t{nv} > uint64_t{nt} * 3) {
    return DataLoss("g3.num_vertices: " + Str(nv) + " vertices cannot all be referenced by " + Str(nt) + " triangles");
  }

  TokenReader br;
  HOLO_RETURN_IF_ERROR(br.Init(bricks_b, kBrickContexts, "g3.bricks"));
  // Every brick costs a symbol: checked before anything is allocated.
  const uint64_t bricks = uint64_t(CeilDiv(nx, kBrick)) * uint64_t(CeilDiv(ny, kBrick)) * uint64_t(CeilDiv(nz, kBrick));
  if (bricks > br.MaxSymbols())
    return DataLoss("g3.bricks: " + Str(bricks) + " bricks cannot fit in " + Str(bricks_b.size()) + " bytes");
  thread_local Field f;
  f.Reset(nx, ny, nz);
  std::vector<size_t> occupied;
  for (int z = 0; z < f.bz; ++z)
    for (int y = 0; y < f.by; ++y)
      for (int x = 0; x < f.bx; ++x) {
        const uint32_t bit = br.Get(f.BrickContext(x, y, z));
        if (!br.ok()) return DataLoss("g3.bricks: coded data is truncated or corrupt");
        if (bit > 1) return DataLoss("g3.bricks: brick flag " + Str(bit) + " is not 0 or 1");
        const size_t b = f.Brick(x, y, z);
        if (bit) {
          if (occupied.size() >= kSurfaceMaxOccupiedBricks)
            return DataLoss("g3.bricks: more than " + Str(kSurfaceMaxOccupiedBricks) + " occupied bricks");
          f.brick_slot[b] = -2;  // occupied; slot given below (after the count is checked)
          occupied.push_back(b);
        }
      }
  HOLO_RETURN_IF_ERROR(br.Finish());
  TokenReader lr;
  HOLO_RETURN_IF_ERROR(lr.Init(labels_b, kLabelContexts, "g3.labels"));
  // Every sample of an occupied brick costs a label symbol.
  if (uint64_t{occupied.size()} > lr.MaxSymbols() / kBrickSamples + 1)
    return DataLoss("g3.bricks: " + Str(occupied.size()) + " occupied bricks cannot fit in " + Str(labels_b.size()) +
                    " bytes of labels");
  for (size_t b : occupied) f.AddSlot(b);
  f.IndexRows();
  bool bad_label = false;
  ForEachSample(f, [&](int x, int y, int z, size_t) {
    const uint32_t lab = lr.Get(static_cast<uint32_t>(LabelContext(f, x, y, z)));
    bad_label |= lab > kInside;
    f.lab[f.P(x, y, z)] = static_cast<uint8_t>(std::min<uint32_t>(lab, kInside));
  });
  if (!lr.ok()) return DataLoss("g3.labels: coded data is truncated or corrupt");
  if (bad_label) return DataLoss("g3.labels: a label is not 0, 1 or 2");
  HOLO_RETURN_IF_ERROR(lr.Finish());
  TokenReader cr;
  HOLO_RETURN_IF_ERROR(cr.Init(crossings_b, kCrossingContexts, "g3.crossings"));
  uint8_t level_of[65];
  LevelTable(levels, level_of);
  bool bad_crossing = false;
  ForEachCrossedEdge(f, [&](int x, int y, int z, int axis, size_t e) {
    if (!cr.ok()) return;
    const int le = EdgeLevels(f, x, y, z, axis, level_of);
    const uint32_t k = le > 1 ? cr.GetValue(static_cast<uint32_t>(std::min(le, static_cast<int>(kCrossingContexts)) - 1)) : 0;
    bad_crossing |= k >= static_cast<uint32_t>(le);
    f.cross[e] = static_cast<int16_t>(k < static_cast<uint32_t>(le) ? k : 0);
    f.cross_levels[e] = static_cast<uint8_t>(le);
  });
  if (!cr.ok()) return DataLoss("g3.crossings: coded data is truncated or corrupt");
  if (bad_crossing) return DataLoss("g3.crossings: a crossing is outside its edge");
  HOLO_RETURN_IF_ERROR(cr.Finish());
  HOLO_RETURN_IF_ERROR(MeshFromField(f, Eigen::Vector3f(origin[0], origin[1], origin[2]), voxel, nv, nt, mesh));
  if (mesh->num_vertices() != nv || mesh->num_triangles() != nt)
    return DataLoss("g3: the surface has " + Str(mesh->num_vertices()) + " vertices and " + Str(mesh->num_triangles()) +
                    " triangles, the prefix says " + Str(nv) + " and " + Str(nt));
  return OkStatus();
}

}  // namespace internal
}  // namespace holo::protocol
