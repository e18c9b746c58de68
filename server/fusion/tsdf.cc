#include "server/fusion/tsdf.h"

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <limits>
#include <cstdlib>
#include <cstring>
#include <string>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#include <immintrin.h>
#endif

#include "common/camera.h"
#include "common/cpu_features.h"
#include "server/fusion/tsdf_internal.h"

namespace holo {
namespace {

std::string Num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%g", v);
  return buf;
}

std::string PodName(const Rig& rig, size_t k) {
  std::string s = "pod " + std::to_string(k);
  if (k < rig.pods.size() && !rig.pods[k].name.empty()) s += " (" + rig.pods[k].name + ")";
  return s;
}

// Interleaves the low 21 bits of the three (offset) block coordinates.
uint64_t MortonCode(const BlockCoord& c) {
  auto spread = [](uint64_t v) {
    v &= 0x1FFFFF;
    v = (v | v << 32) & 0x1F00000000FFFFull;
    v = (v | v << 16) & 0x1F0000FF0000FFull;
    v = (v | v << 8) & 0x100F00F00F00F00Full;
    v = (v | v << 4) & 0x10C30C30C30C30C3ull;
    v = (v | v << 2) & 0x1249249249249249ull;
    return v;
  };
  return spread(static_cast<uint32_t>(c.x + kMaxBlockCoord)) | spread(static_cast<uint32_t>(c.y + kMaxBlockCoord)) << 1 |
         spread(static_cast<uint32_t>(c.z + kMaxBlockCoord)) << 2;
}

// Blocks handled per task: enough work to amortise the hand-off, small
// enough to balance two threads.
constexpr size_t kBlocksPerTask = 8;

// Minimum camera-space depth of a voxel that is projected, metres.
constexpr float kMinProjectZ = 1e-3f;

}  // namespace

Status TsdfOptions::Check() const {
  if (!(voxel_size > 0) || !std::isfinite(voxel_size))
    return InvalidArgument("voxel_size must be > 0, got " + Num(voxel_size));
  if (!(truncation_voxels >= 1) || !std::isfinite(truncation_voxels))
    return InvalidArgument("truncation_voxels must be >= 1, got " + Num(truncation_voxels));
  if (!(behind_band >= 1 && behind_band <= 4))
    return InvalidArgument("behind_band must be in [1, 4], got " + Num(behind_band));
  if (!(behind_noise_sigmas >= 0 && behind_noise_sigmas <= 5))
    return InvalidArgument("behind_noise_sigmas must be in [0, 5], got " + Num(behind_noise_sigmas));
  if (!(depth_noise_at_1m_mm >= 0 && depth_noise_at_1m_mm <= 100))
    return InvalidArgument("depth_noise_at_1m_mm must be in [0, 100], got " + Num(depth_noise_at_1m_mm));
  if (!(max_depth_m > 0) || !(max_depth_m <= 65.535f))
    return InvalidArgument("max_depth_m must be in (0, 65.535], got " + Num(max_depth_m));
  if (!(min_depth_m >= 0) || !(min_depth_m < max_depth_m))
    return InvalidArgument("min_depth_m must be in [0, max_depth_m), got " + Num(min_depth_m));
  if (!(min_weight > 0) || !std::isfinite(min_weight))
    return InvalidArgument("min_weight must be > 0, got " + Num(min_weight));
  if (allocation_min_support < 0 || allocation_min_support > 4)
    return InvalidArgument("allocation_min_support must be in [0, 4], got " + std::to_string(allocation_min_support));
  if (threads < 0) return InvalidArgument("threads must be >= 0, got " + std::to_string(threads));
  return OkStatus();
}

TsdfVolume::TsdfVolume(TsdfOptions options) : options_(options) {
  const Status s = options_.Check();
  HOLO_CHECK_MSG(s.ok(), s.ToString());
  scratch_ = std::make_unique<Scratch>(options_.threads);
}

StatusOr<std::unique_ptr<TsdfVolume>> TsdfVolume::Create(TsdfOptions options) {
  HOLO_RETURN_IF_ERROR(options.Check().WithContext("TsdfOptions"));
  return std::make_unique<TsdfVolume>(options);
}

TsdfVolume::~TsdfVolume() = default;

void TsdfVolume::Reset() {
  blocks_.Clear();
  stats_ = {};
}

Status TsdfVolume::DownsampleInto(int step, TsdfVolume* coarse) const {
  if (coarse == nullptr || coarse == this) return InvalidArgument("DownsampleInto needs a second volume");
  if (step < 1 || step > 8) return InvalidArgument("downsample step must be in [1, 8], got " + std::to_string(step));
  const float want = options_.voxel_size * static_cast<float>(step);
  if (std::abs(coarse->options_.voxel_size - want) > 1e-6f * want)
    return InvalidArgument("coarse voxel_size must be " + std::to_string(want) + " m, got " +
                           std::to_string(coarse->options_.voxel_size));
  const float trunc_m = options_.truncation_voxels * options_.voxel_size;
  const float coarse_trunc_m = coarse->options_.truncation_voxels * coarse->options_.voxel_size;
  if (std::abs(trunc_m - coarse_trunc_m) > 1e-4f * trunc_m)
    return InvalidArgument("coarse truncation must be " + std::to_string(trunc_m) + " m like the fine volume's, got " +
                           std::to_string(coarse_trunc_m));
  coarse->Reset();
  VoxelBlockMap& out = coarse->blocks_;
  auto floor_div = [](int64_t a, int64_t b) { return a >= 0 ? a / b : -((-a + b - 1) / b); };
  // Per coarse block: weighted sums of tsdf and colour, the weight sum and the
  // number of observed fine voxels, per coarse voxel.
  struct Sums {
    float tw[kBlockVoxels], w[kBlockVoxels], r[kBlockVoxels], g[kBlockVoxels], b[kBlockVoxels];
    uint16_t n[kBlockVoxels];
  };
  std::vector<Sums>& sums = coarse->scratch_->downsample_sums_storage<Sums>();
  BlockCoord last{};
  int32_t last_index = VoxelBlockMap::kNotFound;
  const size_t nb = blocks_.size();
  // Without colour (a live site streaming the pods' images) only tsdf and
  // weight are summed (the test does not change within the loop).
  const bool color = options_.integrate_color;
  for (size_t bi = 0; bi < nb; ++bi) {
    const int32_t b = static_cast<int32_t>(bi);
    const BlockCoord bc = blocks_.coord(b);
    const VoxelBlock& fine = blocks_.block(b);
    // Per axis and fine index within the block: the coarse block coordinate
    // and the index within it (the divisions once per block, not per voxel).
    const int64_t base[3] = {int64_t{kBlockSide} * bc.x, int64_t{kBlockSide} * bc.y, int64_t{kBlockSide} * bc.z};
    int32_t cblock[3][kBlockSide];
    int cvox[3][kBlockSide];
    for (int a = 0; a < 3; ++a)
      for (int t = 0; t < kBlockSide; ++t) {
        const int64_t c = floor_div(base[a] + t, step);
        const int64_t cbk = floor_div(c, kBlockSide);
        cblock[a][t] = static_cast<int32_t>(cbk);
        cvox[a][t] = static_cast<int>(c - int64_t{kBlockSide} * cbk);
      }
    // Along a row of the block, fine voxels that fall into the same coarse
    // voxel (a run of `step`) are summed in registers and added once.
    for (int k = 0; k < kBlockSide; ++k) {
      for (int j = 0; j < kBlockSide; ++j) {
        const int row = kBlockSide * (j + kBlockSide * k);
        int i = 0;
        while (i < kBlockSide) {
          const int32_t cbx = cblock[0][i];
          const int cvx = cvox[0][i];
          float tw = 0, ws = 0, rs = 0, gs = 0, bs = 0;
          int cnt = 0;
          for (; i < kBlockSide && cvox[0][i] == cvx && cblock[0][i] == cbx; ++i) {
            const int fv = row + i;
            const float w = fine.weight[fv];
            if (!(w > 0)) continue;
            tw += fine.tsdf[fv] * w;
            ws += w;
            if (color) {
              rs += fine.r[fv] * w;
              gs += fine.g[fv] * w;
              bs += fine.b[fv] * w;
            }
            ++cnt;
          }
          if (cnt == 0) continue;
          const BlockCoord cb{cbx, cblock[1][j], cblock[2][k]};
          if (last_index == VoxelBlockMap::kNotFound || !(cb == last)) {
            bool created = false;
            last_index = out.FindOrAllocate(cb, &created);
            last = cb;
            if (sums.size() <= static_cast<size_t>(last_index)) sums.resize(static_cast<size_t>(last_index) + 1);
            if (created) std::memset(&sums[static_cast<size_t>(last_index)], 0, sizeof(Sums));
          }
          Sums& sm = sums[static_cast<size_t>(last_index)];
          const int cv = cvx + kBlockSide * (cvox[1][j] + kBlockSide * cvox[2][k]);
          sm.tw[cv] += tw;
          sm.w[cv] += ws;
          if (color) {
            sm.r[cv] += rs;
            sm.g[cv] += gs;
            sm.b[cv] += bs;
          }
          sm.n[cv] = static_cast<uint16_t>(sm.n[cv] + cnt);
        }
      }
    }
  }
  for (size_t ci = 0; ci < out.size(); ++ci) {
    const int32_t c = static_cast<int32_t>(ci);
    VoxelBlock& vb = out.block(c);
    const Sums& sm = sums[ci];
    bool has_neg = false, has_pos = false, has_band = false;
    for (int v = 0; v < kBlockVoxels; ++v) {
      if (sm.n[v] == 0) continue;  // stays unobserved (weight 0 from the allocation)
      const float inv = 1.0f / sm.w[v];
      const float t = sm.tw[v] * inv;
      vb.tsdf[v] = t;
      vb.weight[v] = sm.w[v] / static_cast<float>(sm.n[v]);  // mean weight of the observed fine voxels
      if (color) {
        vb.r[v] = static_cast<uint8_t>(sm.r[v] * inv + 0.5f);
        vb.g[v] = static_cast<uint8_t>(sm.g[v] * inv + 0.5f);
        vb.b[v] = static_cast<uint8_t>(sm.b[v] * inv + 0.5f);
      }
      has_neg |= t < 0;
      has_pos |= t >= 0;
      has_band |= t >= 0 && t < kTsdfBandLimit;
    }
    out.set_flags(c, BlockFlagsOf(has_neg, has_pos, has_band));
  }
  return OkStatus();
}

Status TsdfVolume::SmoothInto(TsdfVolume* out) const {
  if (out == nullptr || out == this) return InvalidArgument("SmoothInto needs a second volume");
  if (std::abs(out->options_.voxel_size - options_.voxel_size) > 1e-6f * options_.voxel_size ||
      std::abs(out->options_.truncation_voxels - options_.truncation_voxels) > 1e-6f * options_.truncation_voxels)
    return InvalidArgument("SmoothInto: the output volume must have voxel_size " + std::to_string(options_.voxel_size) +
                           " m and truncation_voxels " + std::to_string(options_.truncation_voxels));
  out->Reset();
  VoxelBlockMap& dst = out->blocks_;
  constexpr int kP = kBlockSide + 2;  // the block and one voxel of each neighbour
  // [0] weight·tsdf, [1] weight: over the padded block, then after the
  // pass along x, then along y (the pass along z gives the result).
  float f[2][kP][kP][kP], fx[2][kP][kP][kBlockSide], fy[2][kP][kBlockSide][kBlockSide];
  for (size_t bi = 0; bi < blocks_.size(); ++bi) {
    const int32_t b = static_cast<int32_t>(bi);
    const BlockCoord bc = blocks_.coord(b);
    const VoxelBlock* nb[3][3][3];
    for (int k = 0; k < 3; ++k)
      for (int j = 0; j < 3; ++j)
        for (int i = 0; i < 3; ++i) {
          const int64_t x = int64_t{bc.x} + i - 1, y = int64_t{bc.y} + j - 1, z = int64_t{bc.z} + k - 1;
          int32_t n = VoxelBlockMap::kNotFound;
          if (BlockCoordInRange(x, y, z))
            n = blocks_.Find({static_cast<int32_t>(x), static_cast<int32_t>(y), static_cast<int32_t>(z)});
          nb[k][j][i] = n == VoxelBlockMap::kNotFound ? nullptr : &blocks_.block(n);
        }
    // Padded coordinate p ∈ [0, kP) is voxel p − 1 of the block: block
    // (p == 0 ? −1 : p == kP − 1 ? +1 : 0), voxel (p − 1) mod kBlockSide.
    auto split = [](int p, int* block, int* voxel) {
      *block = p == 0 ? 0 : p == kP - 1 ? 2 : 1;
      *voxel = p == 0 ? kBlockSide - 1 : p == kP - 1 ? 0 : p - 1;
    };
    for (int z = 0; z < kP; ++z) {
      int bz, vz;
      split(z, &bz, &vz);
      for (int y = 0; y < kP; ++y) {
        int by, vy;
        split(y, &by, &vy);
        for (int x = 0; x < kP; ++x) {
          int bx, vx;
          split(x, &bx, &vx);
          const VoxelBlock* src = nb[bz][by][bx];
          const int v = vx + kBlockSide * (vy + kBlockSide * vz);
          const float w = src ? src->weight[v] : 0.0f;
          f[0][z][y][x] = w > 0 ? w * src->tsdf[v] : 0.0f;
          f[1][z][y][x] = w;
        }
      }
    }
    for (int c = 0; c < 2; ++c) {
      for (int z = 0; z < kP; ++z)
        for (int y = 0; y < kP; ++y)
          for (int x = 0; x < kBlockSide; ++x)
            fx[c][z][y][x] = f[c][z][y][x] + 2 * f[c][z][y][x + 1] + f[c][z][y][x + 2];
      for (int z = 0; z < kP; ++z)
        for (int y = 0; y < kBlockSide; ++y)
          for (int x = 0; x < kBlockSide; ++x)
            fy[c][z][y][x] = fx[c][z][y][x] + 2 * fx[c][z][y + 1][x] + fx[c][z][y + 2][x];
    }
    const VoxelBlock& in = blocks_.block(b);
    const int32_t oi = dst.FindOrAllocate(bc, nullptr, false);
    VoxelBlock& o = dst.block(oi);
    // Colours are copied as they are (ExtractMesh reads them only when the volume fuses colour).
    std::memcpy(o.weight, in.weight, sizeof(o.weight));
    std::memcpy(o.r, in.r, sizeof(o.r));
    std::memcpy(o.g, in.g, sizeof(o.g));
    std::memcpy(o.b, in.b, sizeof(o.b));
    bool has_neg = false, has_pos = false, has_band = false;
    for (int z = 0; z < kBlockSide; ++z)
      for (int y = 0; y < kBlockSide; ++y)
        for (int x = 0; x < kBlockSide; ++x) {
          const int v = x + kBlockSide * (y + kBlockSide * z);
          if (!(in.weight[v] > 0)) {
            o.tsdf[v] = in.tsdf[v];
            continue;
          }
          const float num = fy[0][z][y][x] + 2 * fy[0][z + 1][y][x] + fy[0][z + 2][y][x];
          const float den = fy[1][z][y][x] + 2 * fy[1][z + 1][y][x] + fy[1][z + 2][y][x];
          const float t = std::clamp(num / den, -1.0f, 1.0f);  // den ≥ 8 · the voxel's own weight
          o.tsdf[v] = t;
          has_neg |= t < 0;
          has_pos |= t >= 0;
          has_band |= t >= 0 && t < kTsdfBandLimit;
        }
    dst.set_flags(oi, BlockFlagsOf(has_neg, has_pos, has_band));
  }
  return OkStatus();
}

void TsdfVolume::VoxelAt(int64_t x, int64_t y, int64_t z, float* tsdf, float* weight) const {
  *tsdf = 0;
  *weight = 0;
  auto fdiv = [](int64_t a) { return a >= 0 ? a / kBlockSide : -((-a + kBlockSide - 1) / kBlockSide); };
  const int64_t bx = fdiv(x), by = fdiv(y), bz = fdiv(z);
  if (!BlockCoordInRange(bx, by, bz)) return;
  const int32_t b = blocks_.Find({static_cast<int32_t>(bx), static_cast<int32_t>(by), static_cast<int32_t>(bz)});
  if (b == VoxelBlockMap::kNotFound) return;
  const int i = static_cast<int>((x - bx * kBlockSide) + kBlockSide * (y - by * kBlockSide) +
                                 kBlockSide * kBlockSide * (z - bz * kBlockSide));
  *tsdf = blocks_.block(b).tsdf[i];
  *weight = blocks_.block(b).weight[i];
}

void TsdfVolume::ExportGrid(SdfGrid* out) const {
  const size_t nb = blocks_.size();
  out->voxel_m = options_.voxel_size;
  // Every surface cube has a corner behind the surface: the box of the
  // blocks holding such voxels, one voxel wider on every side, holds every
  // cube marching cubes could use.
  int32_t lo[3] = {INT32_MAX, INT32_MAX, INT32_MAX}, hi[3] = {INT32_MIN, INT32_MIN, INT32_MIN};
  for (size_t b = 0; b < nb; ++b) {
    if (!(blocks_.flags(static_cast<int32_t>(b)) & kBlockHasNegative)) continue;
    const BlockCoord& c = blocks_.coord(static_cast<int32_t>(b));
    const int32_t v[3] = {c.x, c.y, c.z};
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], v[a]);
      hi[a] = std::max(hi[a], v[a]);
    }
  }
  if (lo[0] > hi[0]) {
    out->origin = Eigen::Vector3f::Zero();
    out->nx = out->ny = out->nz = 1;
    out->sdf.assign(1, std::numeric_limits<float>::quiet_NaN());
    return;
  }
  int64_t v0[3];
  for (int a = 0; a < 3; ++a) v0[a] = int64_t{lo[a]} * kBlockSide - 1;
  out->nx = (hi[0] - lo[0] + 1) * kBlockSide + 2;
  out->ny = (hi[1] - lo[1] + 1) * kBlockSide + 2;
  out->nz = (hi[2] - lo[2] + 1) * kBlockSide + 2;
  out->origin = Eigen::Vector3f(static_cast<float>(v0[0]), static_cast<float>(v0[1]), static_cast<float>(v0[2])) *
                options_.voxel_size;
  out->sdf.assign(out->size(), std::numeric_limits<float>::quiet_NaN());
  const float trunc_m = options_.truncation_voxels * options_.voxel_size;
  for (size_t b = 0; b < nb; ++b) {
    const BlockCoord& c = blocks_.coord(static_cast<int32_t>(b));
    const int64_t b0[3] = {int64_t{c.x} * kBlockSide - v0[0], int64_t{c.y} * kBlockSide - v0[1], int64_t{c.z} * kBlockSide - v0[2]};
    // The part of the block inside the box.
    int i0[3], i1[3];
    bool empty = false;
    const int n[3] = {out->nx, out->ny, out->nz};
    for (int a = 0; a < 3; ++a) {
      i0[a] = static_cast<int>(std::clamp<int64_t>(-b0[a], 0, kBlockSide));
      i1[a] = static_cast<int>(std::clamp<int64_t>(n[a] - b0[a], 0, kBlockSide));
      empty |= i0[a] >= i1[a];
    }
    if (empty) continue;
    const VoxelBlock& vb = blocks_.block(static_cast<int32_t>(b));
    for (int k = i0[2]; k < i1[2]; ++k)
      for (int j = i0[1]; j < i1[1]; ++j) {
        float* row = &out->sdf[out->Index(0, static_cast<int>(b0[1]) + j, static_cast<int>(b0[2]) + k)];
        const int r0 = kBlockSide * (j + kBlockSide * k);
        for (int i = i0[0]; i < i1[0]; ++i)
          if (vb.weight[r0 + i] >= options_.min_weight) row[b0[0] + i] = vb.tsdf[r0 + i] * trunc_m;
      }
  }
}

namespace {

// Masks and range-limits one pod's depth into `out` and computes the
// maximum depth of every 8×8 tile (0 = no usable pixel in the tile) and the
// minimum (0 = some pixel of the tile is unusable).
void PrepareDepth(const RgbdFrame& frame, uint16_t min_mm, uint16_t max_mm, std::vector<uint16_t>* out,
                  std::vector<uint16_t>* tile_max, std::vector<uint16_t>* tile_min, int tiles_x, int tiles_y) {
  const int w = frame.depth.width(), h = frame.depth.height();
  // One pixel of padding: the AVX2 path gathers 32-bit words at 16-bit pixels.
  out->resize(static_cast<size_t>(w) * h + 1);
  out->back() = 0;
  tile_max->assign(static_cast<size_t>(tiles_x) * tiles_y, 0);
  tile_min->assign(static_cast<size_t>(tiles_x) * tiles_y, 0xFFFF);
  const bool has_mask = !frame.mask.empty();
  for (int y = 0; y < h; ++y) {
    const uint16_t* src = frame.depth.row(y);
    const uint8_t* m = has_mask ? frame.mask.row(y) : nullptr;
    uint16_t* dst = out->data() + static_cast<size_t>(y) * w;
    uint16_t* tiles = tile_max->data() + static_cast<size_t>(y / kTileSide) * tiles_x;
    uint16_t* mins = tile_min->data() + static_cast<size_t>(y / kTileSide) * tiles_x;
    for (int x = 0; x < w; ++x) {
      uint16_t d = src[x];
      if ((m && m[x] == 0) || d < min_mm || d > max_mm) d = 0;
      dst[x] = d;
      uint16_t& t = tiles[x / kTileSide];
      if (d > t) t = d;
      uint16_t& m = mins[x / kTileSide];
      if (d < m) m = d;  // 0 (an unusable pixel) sticks
    }
  }
}

// Marks usable pixels with a 4-neighbour that is unusable or more than
// `jump_mm` away (image borders count as edges).
void FindDepthEdges(const std::vector<uint16_t>& depth, int w, int h, int jump_mm, std::vector<uint8_t>* edge) {
  edge->resize(depth.size());
  for (int y = 0; y < h; ++y) {
    const uint16_t* row = depth.data() + static_cast<size_t>(y) * w;
    const uint16_t* up = y > 0 ? row - w : nullptr;
    const uint16_t* down = y + 1 < h ? row + w : nullptr;
    uint8_t* out = edge->data() + static_cast<size_t>(y) * w;
    for (int x = 0; x < w; ++x) {
      const int d = row[x];
      if (d == 0) {
        out[x] = 0;
        continue;
      }
      auto far = [&](int n) { return n == 0 || std::abs(n - d) > jump_mm; };
      out[x] = !up || !down || x == 0 || x + 1 == w || far(up[x]) || far(down[x]) || far(row[x - 1]) || far(row[x + 1]);
    }
  }
}

// Collects the blocks crossed by the truncation band of every usable pixel:
// the segment of its viewing ray from depth − trunc to depth + trunc, walked
// through the block grid (Amanatides & Woo). Consecutive pixels mostly hit
// the same blocks, so a small direct-mapped cache drops most repeats before
// they reach the (serial) hash insertion.
void CollectBlocks(const TsdfVolume::PodView& v, const TsdfOptions& o, std::vector<BlockCoord>* out) {
  out->clear();
  constexpr int kCacheSize = 4096;
  std::array<uint64_t, kCacheSize> cache;
  cache.fill(~uint64_t{0});
  const float trunc = o.truncation_voxels * o.voxel_size;
  const float inv_block = 1.0f / (o.voxel_size * kBlockSide);
  const float half = 0.5f / kBlockSide;  // voxel centres sit on the lattice: block b covers [8b − ½, 8b + 7½) voxels
  const int min_support = o.allocation_min_support;
  const int trunc_mm = static_cast<int>(trunc * 1000.0f);
  const Eigen::Matrix3f Rt = v.R.transpose();
  const Eigen::Vector3f c = v.center * inv_block + Eigen::Vector3f::Constant(half);
  for (int py = 0; py < v.height; ++py) {
    const uint16_t* row = v.depth + static_cast<size_t>(py) * v.width;
    for (int px = 0; px < v.width; ++px) {
      if (row[px] == 0) continue;
      if (min_support > 0) {
        // Support: 4-neighbours with depth within the truncation distance.
        const int d0 = row[px];
        auto near = [&](int n) { return n != 0 && std::abs(n - d0) <= trunc_mm; };
        const int support = (px > 0 && near(row[px - 1])) + (px + 1 < v.width && near(row[px + 1])) +
                            (py > 0 && near(row[px - v.width])) + (py + 1 < v.height && near(row[px + v.width]));
        if (support < min_support) continue;
      }
      const float d = row[px] * 0.001f;
      Eigen::Vector2d n((px - v.cx) / v.fx, (py - v.cy) / v.fy);
      if (v.distorted) n = Undistort(v.distortion, n);
      // Ray in block units per metre of camera depth.
      const Eigen::Vector3f dir = Rt * Eigen::Vector3f(static_cast<float>(n.x()), static_cast<float>(n.y()), 1.0f) * inv_block;
      const float z0 = std::max(d - trunc, o.min_depth_m * 0.5f);
      const Eigen::Vector3f q0 = c + dir * z0;
      const Eigen::Vector3f q1 = c + dir * (d + trunc);
      if (!BlockCoordInRange(static_cast<int64_t>(std::floor(q0.x())), static_cast<int64_t>(std::floor(q0.y())),
                             static_cast<int64_t>(std::floor(q0.z()))) ||
          !BlockCoordInRange(static_cast<int64_t>(std::floor(q1.x())), static_cast<int64_t>(std::floor(q1.y())),
                             static_cast<int64_t>(std::floor(q1.z()))))
        continue;
      int b[3] = {static_cast<int>(std::floor(q0.x())), static_cast<int>(std::floor(q0.y())),
                  static_cast<int>(std::floor(q0.z()))};
      const int e[3] = {static_cast<int>(std::floor(q1.x())), static_cast<int>(std::floor(q1.y())),
                        static_cast<int>(std::floor(q1.z()))};
      const Eigen::Vector3f delta = q1 - q0;
      int step[3];
      float t_max[3], t_delta[3];
      for (int a = 0; a < 3; ++a) {
        if (delta[a] > 0) {
          step[a] = 1;
          t_delta[a] = 1.0f / delta[a];
          t_max[a] = (static_cast<float>(b[a]) + 1.0f - q0[a]) * t_delta[a];
        } else if (delta[a] < 0) {
          step[a] = -1;
          t_delta[a] = -1.0f / delta[a];
          t_max[a] = (q0[a] - static_cast<float>(b[a])) * t_delta[a];
        } else {
          step[a] = 0;
          t_delta[a] = INFINITY;
          t_max[a] = INFINITY;
        }
      }
      // A segment crosses at most |Δx| + |Δy| + |Δz| + 1 blocks.
      const int max_steps = std::abs(e[0] - b[0]) + std::abs(e[1] - b[1]) + std::abs(e[2] - b[2]);
      for (int s = 0;; ++s) {
        const BlockCoord bc{b[0], b[1], b[2]};
        const uint64_t key = (static_cast<uint64_t>(static_cast<uint32_t>(b[0] + kMaxBlockCoord)) << 42) |
                             (static_cast<uint64_t>(static_cast<uint32_t>(b[1] + kMaxBlockCoord)) << 21) |
                             static_cast<uint64_t>(static_cast<uint32_t>(b[2] + kMaxBlockCoord));
        uint64_t& slot = cache[(key * 0x9E3779B97F4A7C15ull) >> 52];
        if (slot != key) {
          slot = key;
          out->push_back(bc);
        }
        if (s >= max_steps) break;
        const int a = t_max[0] < t_max[1] ? (t_max[0] < t_max[2] ? 0 : 2) : (t_max[1] < t_max[2] ? 1 : 2);
        if (t_max[a] > 1.0f) break;
        b[a] += step[a];
        t_max[a] += t_delta[a];
      }
    }
  }
}

// Accumulators of one block over all views of one frame. Colour is
// accumulated only inside the truncation band (|sdf| < trunc): voxels further
// in front see whatever surface lies behind them.
struct alignas(16) BlockAccumulator {
  float tsdf[kBlockVoxels];
  float weight[kBlockVoxels];
  float color_weight[kBlockVoxels];
  float r[kBlockVoxels], g[kBlockVoxels], b[kBlockVoxels];
  void Clear(bool with_color) {
    // tsdf and weight come first: without colour only they are used.
    std::memset(static_cast<void*>(this), 0, with_color ? sizeof(*this) : 2 * sizeof(tsdf));
  }
};

inline void AddColor(BlockAccumulator* acc, int idx, const uint8_t* c) {
  acc->r[idx] += c[0];
  acc->g[idx] += c[1];
  acc->b[idx] += c[2];
  acc->color_weight[idx] += 1.0f;
}

// Colour of the voxel at `p` (depth-camera coordinates) in a pod whose colour
// camera differs from its depth camera; the nearest edge pixel if it falls
// outside the colour image.
const uint8_t* NonRegisteredColor(const TsdfVolume::PodView& v, const Eigen::Vector3f& p) {
  const Eigen::Vector3f q = v.Rc * p + v.tc;
  if (q.z() <= kMinProjectZ) return nullptr;
  Eigen::Vector2d n(q.x() / q.z(), q.y() / q.z());
  if (v.color_distorted) n = Distort(v.color_distortion, n);
  const float cu = static_cast<float>(v.cfx * n.x() + v.ccx) + 0.5f;
  const float cw = static_cast<float>(v.cfy * n.y() + v.ccy) + 0.5f;
  const int iu = std::clamp(static_cast<int>(std::floor(cu)), 0, v.cwidth - 1);
  const int iw = std::clamp(static_cast<int>(std::floor(cw)), 0, v.cheight - 1);
  return v.color + 3 * (static_cast<size_t>(iw) * v.cwidth + iu);
}

// How deep behind the measured surface an observation counts (metres) at a
// pixel of depth d (mm): base + per_mm2 · d · d (TsdfOptions::behind_band,
// behind_noise_sigmas). Every integration path computes it in this order.
struct BehindBand {
  float base = 0;
  float per_mm2 = 0;
  float At(float d_mm) const { return base + per_mm2 * d_mm * d_mm; }
};

// A cube of voxels of a block: local voxel coordinates [i0, i0 + side) ×
// [j0, j0 + side) × [k0, k0 + side); side is 4 or 8 (a multiple of 4).
struct SubBox {
  int i0 = 0, j0 = 0, k0 = 0, side = kBlockSide;
};

// Projects the voxels of one block (first voxel centre at `origin`, world)
// into one view and accumulates their truncated signed distances. General
// path: any camera, optional edge filter.
template <bool kDistorted, bool kRegistered>
void IntegrateView(const TsdfVolume::PodView& v, const Eigen::Vector3f& origin, float voxel, float trunc,
                   const BehindBand& behind, const SubBox& box, BlockAccumulator* acc) {
  const Eigen::Vector3f p0 = v.R * origin + v.t;
  const Eigen::Vector3f dx = v.R.col(0) * voxel, dy = v.R.col(1) * voxel, dz = v.R.col(2) * voxel;
  const float inv_trunc = 1.0f / trunc;
  const float wf = static_cast<float>(v.width), hf = static_cast<float>(v.height);
  for (int k = box.k0; k < box.k0 + box.side; ++k) {
    for (int j = box.j0; j < box.j0 + box.side; ++j) {
      Eigen::Vector3f p = p0 + dx * static_cast<float>(box.i0) + dy * static_cast<float>(j) + dz * static_cast<float>(k);
      const int row = kBlockSide * j + kBlockSide * kBlockSide * k;
      for (int i = box.i0; i < box.i0 + box.side; ++i, p += dx) {
        if (p.z() <= kMinProjectZ) continue;
        float u, w;
        if constexpr (kDistorted) {
          const Eigen::Vector2d n = Distort(v.distortion, Eigen::Vector2d(p.x() / p.z(), p.y() / p.z()));
          u = static_cast<float>(v.fx * n.x() + v.cx) + 0.5f;
          w = static_cast<float>(v.fy * n.y() + v.cy) + 0.5f;
        } else {
          const float inv_z = 1.0f / p.z();
          u = v.fx * p.x() * inv_z + v.cx + 0.5f;
          w = v.fy * p.y() * inv_z + v.cy + 0.5f;
        }
        if (!(u >= 0.0f && u < wf && w >= 0.0f && w < hf)) continue;
        const size_t pixel = static_cast<size_t>(static_cast<int>(w)) * v.width + static_cast<size_t>(u);
        const uint16_t d = v.depth[pixel];
        if (d == 0) continue;
        const float sdf = static_cast<float>(d) * 0.001f - p.z();
        if (sdf < -behind.At(static_cast<float>(d))) continue;
        if (sdf < 0 && v.edge && v.edge[pixel]) continue;
        const int idx = row + i;
        acc->tsdf[idx] += std::max(-1.0f, std::min(1.0f, sdf * inv_trunc));
        acc->weight[idx] += 1.0f;
        if (sdf >= trunc || !v.with_color) continue;
        const uint8_t* c = kRegistered ? v.color + 3 * pixel : NonRegisteredColor(v, p);
        if (c) AddColor(acc, idx, c);
      }
    }
  }
}

#if defined(__SSE2__)
// The hot path (undistorted, registered, no edge filter), four voxels at a
// time with SSE2 (part of every x86-64 CPU). Same arithmetic as the general
// path up to float rounding order.
void IntegrateViewSse2(const TsdfVolume::PodView& v, const Eigen::Vector3f& origin, float voxel, float trunc,
                       const BehindBand& behind, const SubBox& box, BlockAccumulator* acc) {
  const Eigen::Vector3f p0 = v.R * origin + v.t;
  const Eigen::Vector3f dx = v.R.col(0) * voxel, dy = v.R.col(1) * voxel, dz = v.R.col(2) * voxel;
  const __m128 lane = _mm_setr_ps(0, 1, 2, 3);
  const __m128 dxx = _mm_set1_ps(dx.x()), dxy = _mm_set1_ps(dx.y()), dxz = _mm_set1_ps(dx.z());
  const __m128 fx = _mm_set1_ps(v.fx), fy = _mm_set1_ps(v.fy);
  const __m128 cx = _mm_set1_ps(v.cx + 0.5f), cy = _mm_set1_ps(v.cy + 0.5f);
  const __m128 wf = _mm_set1_ps(static_cast<float>(v.width)), hf = _mm_set1_ps(static_cast<float>(v.height));
  const __m128 zero = _mm_setzero_ps(), one = _mm_set1_ps(1.0f), min_z = _mm_set1_ps(kMinProjectZ);
  const __m128 mm = _mm_set1_ps(0.001f), pos_trunc = _mm_set1_ps(trunc);
  const __m128 band_base = _mm_set1_ps(behind.base), band_per_mm2 = _mm_set1_ps(behind.per_mm2);
  const __m128 minus_one = _mm_set1_ps(-1.0f);
  const __m128 inv_trunc = _mm_set1_ps(1.0f / trunc);
  alignas(16) int32_t pix[4];
  alignas(16) float depth[4];
  for (int k = box.k0; k < box.k0 + box.side; ++k) {
    for (int j = box.j0; j < box.j0 + box.side; ++j) {
      const Eigen::Vector3f pr = p0 + dy * static_cast<float>(j) + dz * static_cast<float>(k);
      const int row = kBlockSide * j + kBlockSide * kBlockSide * k;
      for (int half = box.i0; half < box.i0 + box.side; half += 4) {
        const __m128 li = _mm_add_ps(lane, _mm_set1_ps(static_cast<float>(half)));
        const __m128 px = _mm_add_ps(_mm_set1_ps(pr.x()), _mm_mul_ps(li, dxx));
        const __m128 py = _mm_add_ps(_mm_set1_ps(pr.y()), _mm_mul_ps(li, dxy));
        const __m128 pz = _mm_add_ps(_mm_set1_ps(pr.z()), _mm_mul_ps(li, dxz));
        __m128 ok = _mm_cmpgt_ps(pz, min_z);
        const __m128 inv_z = _mm_div_ps(one, pz);
        const __m128 u = _mm_add_ps(_mm_mul_ps(_mm_mul_ps(fx, px), inv_z), cx);
        const __m128 w = _mm_add_ps(_mm_mul_ps(_mm_mul_ps(fy, py), inv_z), cy);
        ok = _mm_and_ps(ok, _mm_and_ps(_mm_cmpge_ps(u, zero), _mm_cmplt_ps(u, wf)));
        ok = _mm_and_ps(ok, _mm_and_ps(_mm_cmpge_ps(w, zero), _mm_cmplt_ps(w, hf)));
        const int ok_bits = _mm_movemask_ps(ok);
        if (ok_bits == 0) continue;
        // Pixel index in float arithmetic (exact below 2^24 pixels): SSE2 has
        // no 32-bit integer multiply.
        const __m128 fu = _mm_cvtepi32_ps(_mm_cvttps_epi32(_mm_and_ps(ok, u)));
        const __m128 fw = _mm_cvtepi32_ps(_mm_cvttps_epi32(_mm_and_ps(ok, w)));
        _mm_store_si128(reinterpret_cast<__m128i*>(pix), _mm_cvttps_epi32(_mm_add_ps(_mm_mul_ps(fw, wf), fu)));
        // Lanes outside the image read pixel 0 (always valid) and are masked
        // out afterwards: no unpredictable branch per lane.
        for (int l = 0; l < 4; ++l) depth[l] = static_cast<float>(v.depth[pix[l]]);
        const __m128 d = _mm_and_ps(ok, _mm_load_ps(depth));
        const __m128 sdf = _mm_sub_ps(_mm_mul_ps(d, mm), pz);
        const __m128 band = _mm_add_ps(band_base, _mm_mul_ps(_mm_mul_ps(band_per_mm2, d), d));
        const __m128 upd = _mm_and_ps(_mm_cmpgt_ps(d, zero), _mm_cmpge_ps(sdf, _mm_sub_ps(zero, band)));
        const int upd_bits = _mm_movemask_ps(upd);
        if (upd_bits == 0) continue;
        const __m128 t = _mm_max_ps(minus_one, _mm_min_ps(one, _mm_mul_ps(sdf, inv_trunc)));
        float* at = acc->tsdf + row + half;
        float* aw = acc->weight + row + half;
        _mm_store_ps(at, _mm_add_ps(_mm_load_ps(at), _mm_and_ps(upd, t)));
        _mm_store_ps(aw, _mm_add_ps(_mm_load_ps(aw), _mm_and_ps(upd, one)));
        if (!v.with_color) continue;
        const int near_bits = upd_bits & _mm_movemask_ps(_mm_cmplt_ps(sdf, pos_trunc));
        for (int l = 0; l < 4; ++l)
          if ((near_bits >> l) & 1) AddColor(acc, row + half + l, v.color + 3 * static_cast<size_t>(pix[l]));
      }
    }
  }
}
#endif
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#define HOLO_FUSION_AVX2 1
// The hot path eight voxels at a time with AVX2 (hardware gather of the
// depth), chosen at run time when the CPU has it. The same operations in the
// same order as the SSE2 path (no FMA), so both give bit-identical volumes.
// A 4³ sub-block is handled two rows per vector.
template <bool kColor>
__attribute__((target("avx2"))) void IntegrateViewAvx2(const TsdfVolume::PodView& v, const Eigen::Vector3f& origin,
                                                       float voxel, float trunc, const BehindBand& behind,
                                                       const SubBox& box, BlockAccumulator* acc) {
  const Eigen::Vector3f p0 = v.R * origin + v.t;
  const Eigen::Vector3f dx = v.R.col(0) * voxel, dy = v.R.col(1) * voxel, dz = v.R.col(2) * voxel;
  const bool full = box.side == 8;
  const __m256 lane = full ? _mm256_setr_ps(0, 1, 2, 3, 4, 5, 6, 7) : _mm256_setr_ps(0, 1, 2, 3, 0, 1, 2, 3);
  const __m256 li = full ? lane : _mm256_add_ps(lane, _mm256_set1_ps(static_cast<float>(box.i0)));
  const __m256 dxx = _mm256_set1_ps(dx.x()), dxy = _mm256_set1_ps(dx.y()), dxz = _mm256_set1_ps(dx.z());
  const __m256 fx = _mm256_set1_ps(v.fx), fy = _mm256_set1_ps(v.fy);
  const __m256 cx = _mm256_set1_ps(v.cx + 0.5f), cy = _mm256_set1_ps(v.cy + 0.5f);
  const __m256 wf = _mm256_set1_ps(static_cast<float>(v.width)), hf = _mm256_set1_ps(static_cast<float>(v.height));
  const __m256 zero = _mm256_setzero_ps(), one = _mm256_set1_ps(1.0f), min_z = _mm256_set1_ps(kMinProjectZ);
  const __m256 mm = _mm256_set1_ps(0.001f), pos_trunc = _mm256_set1_ps(trunc);
  const __m256 band_base = _mm256_set1_ps(behind.base), band_per_mm2 = _mm256_set1_ps(behind.per_mm2);
  const __m256 minus_one = _mm256_set1_ps(-1.0f);
  const __m256 inv_trunc = _mm256_set1_ps(1.0f / trunc);
  const __m256i low16 = _mm256_set1_epi32(0xFFFF);
  const int* depth_words = reinterpret_cast<const int*>(v.depth);  // v.depth is padded by one pixel
  const int row_step = full ? 1 : 2;
  for (int k = box.k0; k < box.k0 + box.side; ++k) {
    for (int j = box.j0; j < box.j0 + box.side; j += row_step) {
      const Eigen::Vector3f pr0 = p0 + dy * static_cast<float>(j) + dz * static_cast<float>(k);
      const Eigen::Vector3f pr1 = full ? pr0 : Eigen::Vector3f(p0 + dy * static_cast<float>(j + 1) + dz * static_cast<float>(k));
      const __m256 px = _mm256_add_ps(_mm256_setr_m128(_mm_set1_ps(pr0.x()), _mm_set1_ps(pr1.x())), _mm256_mul_ps(li, dxx));
      const __m256 py = _mm256_add_ps(_mm256_setr_m128(_mm_set1_ps(pr0.y()), _mm_set1_ps(pr1.y())), _mm256_mul_ps(li, dxy));
      const __m256 pz = _mm256_add_ps(_mm256_setr_m128(_mm_set1_ps(pr0.z()), _mm_set1_ps(pr1.z())), _mm256_mul_ps(li, dxz));
      __m256 ok = _mm256_cmp_ps(pz, min_z, _CMP_GT_OQ);
      const __m256 inv_z = _mm256_div_ps(one, pz);
      const __m256 u = _mm256_add_ps(_mm256_mul_ps(_mm256_mul_ps(fx, px), inv_z), cx);
      const __m256 w = _mm256_add_ps(_mm256_mul_ps(_mm256_mul_ps(fy, py), inv_z), cy);
      ok = _mm256_and_ps(ok, _mm256_and_ps(_mm256_cmp_ps(u, zero, _CMP_GE_OQ), _mm256_cmp_ps(u, wf, _CMP_LT_OQ)));
      ok = _mm256_and_ps(ok, _mm256_and_ps(_mm256_cmp_ps(w, zero, _CMP_GE_OQ), _mm256_cmp_ps(w, hf, _CMP_LT_OQ)));
      if (_mm256_movemask_ps(ok) == 0) continue;
      const __m256 fu = _mm256_cvtepi32_ps(_mm256_cvttps_epi32(_mm256_and_ps(ok, u)));
      const __m256 fw = _mm256_cvtepi32_ps(_mm256_cvttps_epi32(_mm256_and_ps(ok, w)));
      const __m256i idx = _mm256_cvttps_epi32(_mm256_add_ps(_mm256_mul_ps(fw, wf), fu));
      // Lanes outside the image read pixel 0 and are masked out afterwards.
      const __m256i raw = _mm256_and_si256(_mm256_i32gather_epi32(depth_words, idx, 2), low16);
      const __m256 d = _mm256_and_ps(ok, _mm256_cvtepi32_ps(raw));
      const __m256 sdf = _mm256_sub_ps(_mm256_mul_ps(d, mm), pz);
      const __m256 band = _mm256_add_ps(band_base, _mm256_mul_ps(_mm256_mul_ps(band_per_mm2, d), d));
      const __m256 upd = _mm256_and_ps(_mm256_cmp_ps(d, zero, _CMP_GT_OQ),
                                       _mm256_cmp_ps(sdf, _mm256_sub_ps(zero, band), _CMP_GE_OQ));
      const __m256 t =
          _mm256_and_ps(upd, _mm256_max_ps(minus_one, _mm256_min_ps(one, _mm256_mul_ps(sdf, inv_trunc))));
      const __m256 wt = _mm256_and_ps(upd, one);
      const int row0 = kBlockSide * j + kBlockSide * kBlockSide * k + box.i0;
      const int row1 = full ? row0 + 4 : row0 + kBlockSide;  // accumulator index of lane 4
      // Adds the lanes of `x` to acc array `base` (lanes 0–3 at row0, 4–7 at row1).
      auto add = [row0, row1](float* base, __m256 x) __attribute__((target("avx2"))) {
        _mm_storeu_ps(base + row0, _mm_add_ps(_mm_loadu_ps(base + row0), _mm256_castps256_ps128(x)));
        _mm_storeu_ps(base + row1, _mm_add_ps(_mm_loadu_ps(base + row1), _mm256_extractf128_ps(x, 1)));
      };
      add(acc->tsdf, t);
      add(acc->weight, wt);
      if constexpr (!kColor) continue;
      const __m256 near = _mm256_and_ps(upd, _mm256_cmp_ps(sdf, pos_trunc, _CMP_LT_OQ));
      if (_mm256_movemask_ps(near) == 0) continue;
      const __m256i rgb = _mm256_mask_i32gather_epi32(_mm256_setzero_si256(), reinterpret_cast<const int*>(v.color_words),
                                                      idx, _mm256_castps_si256(near), 4);
      const __m256i byte = _mm256_set1_epi32(0xFF);
      add(acc->r, _mm256_cvtepi32_ps(_mm256_and_si256(rgb, byte)));
      add(acc->g, _mm256_cvtepi32_ps(_mm256_and_si256(_mm256_srli_epi32(rgb, 8), byte)));
      add(acc->b, _mm256_cvtepi32_ps(_mm256_srli_epi32(rgb, 16)));
      add(acc->color_weight, _mm256_and_ps(near, one));
    }
  }
}

#endif

enum class BlockView { kSkip, kFreeSpace, kProject };

// Image footprint of a box of voxel centres in one (undistorted) view: the
// range of its projected corners and of their camera depths. `behind` = a
// corner is at or behind the camera plane (the footprint is then unbounded).
struct Footprint {
  float umin = INFINITY, umax = -INFINITY, vmin = INFINITY, vmax = -INFINITY, zmin = INFINITY, zmax = -INFINITY;
  bool behind = false;
  void Add(float u, float w, float z, bool b) {
    umin = std::min(umin, u);
    umax = std::max(umax, u);
    vmin = std::min(vmin, w);
    vmax = std::max(vmax, w);
    zmin = std::min(zmin, z);
    zmax = std::max(zmax, z);
    behind |= b;
  }
};

// How view `v` sees a box of voxel centres with footprint `f`: kSkip if no
// voxel can receive an update (outside the image, over pixels without usable
// depth, or entirely more than `trunc` behind the observed surface);
// kFreeSpace if every voxel projects onto a usable pixel more than `trunc`
// behind it (each voxel gets tsdf +1, weight 1, no colour: exactly what
// projecting them would give); kProject otherwise.
BlockView ClassifyFootprint(const TsdfVolume::PodView& v, const Footprint& f, float trunc) {
  if (f.behind) return BlockView::kProject;  // straddles the camera plane
  // Pixels a voxel can round to: [floor(u + ½)] over the projected range
  // (the projection of the box is convex and holds every voxel's projection).
  const int ux0 = static_cast<int>(std::floor(f.umin + 0.5f)), ux1 = static_cast<int>(std::floor(f.umax + 0.5f));
  const int uy0 = static_cast<int>(std::floor(f.vmin + 0.5f)), uy1 = static_cast<int>(std::floor(f.vmax + 0.5f));
  const int x0 = std::max(0, ux0), x1 = std::min(v.width - 1, ux1);
  const int y0 = std::max(0, uy0), y1 = std::min(v.height - 1, uy1);
  if (x0 > x1 || y0 > y1) return BlockView::kSkip;
  uint16_t dmax = 0, dmin = 0xFFFF;
  for (int ty = y0 / kTileSide; ty <= y1 / kTileSide; ++ty)
    for (int tx = x0 / kTileSide; tx <= x1 / kTileSide; ++tx) {
      dmax = std::max(dmax, v.tile_max[ty * v.tiles_x + tx]);
      dmin = std::min(dmin, v.tile_min[ty * v.tiles_x + tx]);
    }
  if (dmax == 0) return BlockView::kSkip;
  if (f.zmin - trunc > static_cast<float>(dmax) * 0.001f) return BlockView::kSkip;
  const bool inside = ux0 >= 0 && ux1 < v.width && uy0 >= 0 && uy1 < v.height;
  // A small margin keeps float rounding in the per-voxel path from making a
  // voxel's distance fall just short of the truncation.
  if (inside && dmin > 0 && static_cast<float>(dmin) * 0.001f - f.zmax > trunc * 1.001f + 1e-4f)
    return BlockView::kFreeSpace;
  return BlockView::kProject;
}

// A block's voxel centres projected on a 3×3×3 lattice (local voxel
// coordinates 0, 3.5 and 7 on each axis): the corners of the whole block and
// of its eight 4³ sub-blocks (each sub-block's box [0, 3.5] or [3.5, 7] holds
// its voxel centres).
struct BlockLattice {
  float u[27], w[27], z[27];
  bool behind[27];
  static int Index(int a, int b, int c) { return a + 3 * b + 9 * c; }
  void Project(const TsdfVolume::PodView& v, const Eigen::Vector3f& origin, float voxel) {
    const Eigen::Vector3f p0 = v.R * origin + v.t;
    const float h = 0.5f * (kBlockSide - 1) * voxel;
    const Eigen::Vector3f dx = v.R.col(0) * h, dy = v.R.col(1) * h, dz = v.R.col(2) * h;
    for (int c = 0; c < 3; ++c)
      for (int b = 0; b < 3; ++b)
        for (int a = 0; a < 3; ++a) {
          const Eigen::Vector3f p = p0 + dx * static_cast<float>(a) + dy * static_cast<float>(b) + dz * static_cast<float>(c);
          const int i = Index(a, b, c);
          behind[i] = p.z() <= kMinProjectZ;
          const float inv_z = 1.0f / p.z();
          u[i] = v.fx * p.x() * inv_z + v.cx;
          w[i] = v.fy * p.y() * inv_z + v.cy;
          z[i] = p.z();
        }
  }
  // Footprint of the box with lattice corners (a0..a0+n, b0..b0+n, c0..c0+n).
  Footprint Box(int a0, int b0, int c0, int n) const {
    Footprint f;
    for (int c = c0; c <= c0 + n; c += n)
      for (int b = b0; b <= b0 + n; b += n)
        for (int a = a0; a <= a0 + n; a += n) {
          const int i = Index(a, b, c);
          f.Add(u[i], w[i], z[i], behind[i]);
        }
    return f;
  }
};

}  // namespace

Status TsdfVolume::Integrate(const Rig& rig, const RgbdFrameSet& frames) {
  // Validate everything before touching the volume.
  if (rig.pods.empty()) return InvalidArgument("rig has no pods");
  if (frames.frames.size() != rig.pods.size())
    return InvalidArgument("frame set has " + std::to_string(frames.frames.size()) + " pods but the rig has " +
                           std::to_string(rig.pods.size()));
  for (size_t k = 0; k < rig.pods.size(); ++k) {
    const PodCalibration& pod = rig.pods[k];
    const RgbdFrame& f = frames.frames[k];
    HOLO_RETURN_IF_ERROR(pod.depth.Check().WithContext(PodName(rig, k) + " depth intrinsics"));
    HOLO_RETURN_IF_ERROR(pod.color.Check().WithContext(PodName(rig, k) + " color intrinsics"));
    auto size = [](int w, int h) { return std::to_string(w) + "x" + std::to_string(h); };
    if (f.depth.width() != pod.depth.width || f.depth.height() != pod.depth.height)
      return InvalidArgument(PodName(rig, k) + ": depth image is " + size(f.depth.width(), f.depth.height()) +
                             " but the rig says " + size(pod.depth.width, pod.depth.height));
    if (f.color.width() != pod.color.width || f.color.height() != pod.color.height)
      return InvalidArgument(PodName(rig, k) + ": color image is " + size(f.color.width(), f.color.height()) +
                             " but the rig says " + size(pod.color.width, pod.color.height));
    if (!f.mask.empty() && (f.mask.width() != f.depth.width() || f.mask.height() != f.depth.height()))
      return InvalidArgument(PodName(rig, k) + ": mask is " + size(f.mask.width(), f.mask.height()) +
                             " but depth is " + size(f.depth.width(), f.depth.height()));
  }

  Scratch& s = *scratch_;
  const size_t num_pods = rig.pods.size();
  const float trunc = options_.truncation_voxels * options_.voxel_size;
  BehindBand behind;
  behind.base = trunc * options_.behind_band;
  // σ(d) = σ1 · d², d in metres; per mm² of depth: σ1 [mm] · 1e-3 [m/mm] · 1e-6.
  behind.per_mm2 = options_.behind_noise_sigmas * options_.depth_noise_at_1m_mm * 1e-9f;
  const auto min_mm = static_cast<uint16_t>(std::ceil(options_.min_depth_m * 1000.0f));
  const auto max_mm = static_cast<uint16_t>(std::floor(options_.max_depth_m * 1000.0f));
  s.views.resize(num_pods);
  s.masked_depth.resize(num_pods);
  s.tile_max.resize(num_pods);
  s.tile_min.resize(num_pods);
  s.edge.resize(num_pods);
  s.pod_blocks.resize(num_pods);
  s.color_words.resize(num_pods);
#if defined(HOLO_FUSION_AVX2)
  const bool use_avx2 = CpuHasAvx2() && !std::getenv("HOLO_FUSION_NO_AVX2");
#endif
  for (size_t k = 0; k < num_pods; ++k) {
    const PodCalibration& pod = rig.pods[k];
    PodView& v = s.views[k];
    const Pose depth_from_world = pod.world_from_depth.inverse();
    v.R = depth_from_world.linear();
    v.t = depth_from_world.translation();
    v.center = pod.world_from_depth.translation();
    v.fx = static_cast<float>(pod.depth.fx);
    v.fy = static_cast<float>(pod.depth.fy);
    v.cx = static_cast<float>(pod.depth.cx);
    v.cy = static_cast<float>(pod.depth.cy);
    v.width = pod.depth.width;
    v.height = pod.depth.height;
    v.distorted = pod.depth.HasDistortion();
    v.distortion = pod.depth.distortion;
    v.registered = pod.IsRegistered();
    v.Rc = pod.color_from_depth.linear();
    v.tc = pod.color_from_depth.translation();
    v.cfx = static_cast<float>(pod.color.fx);
    v.cfy = static_cast<float>(pod.color.fy);
    v.ccx = static_cast<float>(pod.color.cx);
    v.ccy = static_cast<float>(pod.color.cy);
    v.cwidth = pod.color.width;
    v.cheight = pod.color.height;
    v.color_distorted = pod.color.HasDistortion();
    v.color_distortion = pod.color.distortion;
    v.color = frames.frames[k].color.data();
    v.tiles_x = (v.width + kTileSide - 1) / kTileSide;
    v.tiles_y = (v.height + kTileSide - 1) / kTileSide;
  }

  // 1. Per pod (in parallel): mask the depth, tile maxima, candidate blocks.
  const auto t0 = std::chrono::steady_clock::now();
  s.pool.Run(num_pods, [&](size_t k, int) {
    PrepareDepth(frames.frames[k], min_mm, max_mm, &s.masked_depth[k], &s.tile_max[k], &s.tile_min[k], s.views[k].tiles_x,
                 s.views[k].tiles_y);
    s.views[k].depth = s.masked_depth[k].data();
    s.views[k].color_words = nullptr;
    s.views[k].avx2 = false;
    s.views[k].with_color = options_.integrate_color;
#if defined(HOLO_FUSION_AVX2)
    s.views[k].avx2 = use_avx2 && s.views[k].registered && !s.views[k].distorted;
    if (s.views[k].avx2 && options_.integrate_color) {
      const size_t n = static_cast<size_t>(s.views[k].width) * s.views[k].height;
      std::vector<uint32_t>& words = s.color_words[k];
      words.resize(n);
      const uint8_t* c = s.views[k].color;
      for (size_t i = 0; i < n; ++i)
        words[i] = uint32_t{c[3 * i]} | uint32_t{c[3 * i + 1]} << 8 | uint32_t{c[3 * i + 2]} << 16;
      s.views[k].color_words = words.data();
    }
#endif
    s.views[k].tile_max = s.tile_max[k].data();
    s.views[k].tile_min = s.tile_min[k].data();
    if (options_.ignore_behind_depth_edges) {
      FindDepthEdges(s.masked_depth[k], s.views[k].width, s.views[k].height, 1 << 20,
                     &s.edge[k]);
      s.views[k].edge = s.edge[k].data();
    } else {
      s.views[k].edge = nullptr;
    }
    CollectBlocks(s.views[k], options_, &s.pod_blocks[k]);
  });

  const auto t1 = std::chrono::steady_clock::now();
  // 2. Serial: allocate the blocks, in pod order so block indices (and the
  // mesh's vertex order) do not depend on the thread count.
  ++s.stamp;
  if (s.stamp == 0) {  // wrapped: forget old stamps
    std::fill(s.touched_stamp.begin(), s.touched_stamp.end(), 0u);
    s.stamp = 1;
  }
  s.active.clear();
  stats_ = {};
  for (size_t k = 0; k < num_pods; ++k) {
    for (const BlockCoord& c : s.pod_blocks[k]) {
      bool created = false;
      // New blocks are not cleared here: the merge below writes every voxel
      // of every active block (serial memory traffic saved).
      const int32_t b = blocks_.FindOrAllocate(c, &created, /*clear=*/false);
      if (static_cast<size_t>(b) >= s.touched_stamp.size()) s.touched_stamp.resize(static_cast<size_t>(b) + 1, 0u);
      if (static_cast<size_t>(b) >= s.fresh.size()) s.fresh.resize(static_cast<size_t>(b) + 1, 0);
      if (created) s.fresh[static_cast<size_t>(b)] = 1;
      if (s.touched_stamp[static_cast<size_t>(b)] != s.stamp) {
        s.touched_stamp[static_cast<size_t>(b)] = s.stamp;
        s.active.push_back(b);
        stats_.blocks_allocated += created;
      }
    }
  }
  stats_.blocks_touched = s.active.size();
  // Integrate in Morton order: neighbouring blocks project to neighbouring
  // pixels in every view, so consecutive blocks reuse cached depth and colour.
  s.order.resize(s.active.size());
  for (size_t a = 0; a < s.active.size(); ++a) {
    const BlockCoord& c = blocks_.coord(s.active[a]);
    s.order[a] = {MortonCode(c), s.active[a]};
  }
  std::sort(s.order.begin(), s.order.end());
  for (size_t a = 0; a < s.active.size(); ++a) s.active[a] = s.order[a].second;
  const auto t2 = std::chrono::steady_clock::now();

  // 3. Per block (in parallel): project its voxels into every view that can
  // see it, then merge the frame's observations into the stored averages.
  const float voxel = options_.voxel_size;
  const int threads = s.pool.num_threads();
  s.thread_block_views.assign(static_cast<size_t>(threads), 0);
  s.thread_skipped.assign(static_cast<size_t>(threads), 0);
  s.thread_free.assign(static_cast<size_t>(threads), 0);
  s.thread_subs.assign(static_cast<size_t>(threads), 0);
  const size_t num_tasks = (s.active.size() + kBlocksPerTask - 1) / kBlocksPerTask;
  const bool with_color = options_.integrate_color;
  s.pool.Run(num_tasks, [&](size_t task, int thread) {
    BlockAccumulator acc;
    BlockLattice lattice;
    const size_t end = std::min(s.active.size(), (task + 1) * kBlocksPerTask);
    for (size_t a = task * kBlocksPerTask; a < end; ++a) {
      const int32_t b = s.active[a];
      const BlockCoord& bc = blocks_.coord(b);
      const Eigen::Vector3f lo = Eigen::Vector3f(static_cast<float>(bc.x), static_cast<float>(bc.y),
                                                 static_cast<float>(bc.z)) * (voxel * kBlockSide);
      acc.Clear(with_color);
      for (const PodView& v : s.views) {
        auto project = [&](const SubBox& box) {
#if defined(HOLO_FUSION_AVX2)
          if (v.avx2 && !v.edge) {
            if (with_color) IntegrateViewAvx2<true>(v, lo, voxel, trunc, behind, box, &acc);
            else IntegrateViewAvx2<false>(v, lo, voxel, trunc, behind, box, &acc);
            return;
          }
#endif
#if defined(__SSE2__)
          if (!v.distorted && v.registered && !v.edge) {
            IntegrateViewSse2(v, lo, voxel, trunc, behind, box, &acc);
            return;
          }
#endif
          if (v.distorted) {
            if (v.registered) IntegrateView<true, true>(v, lo, voxel, trunc, behind, box, &acc);
            else IntegrateView<true, false>(v, lo, voxel, trunc, behind, box, &acc);
          } else {
            if (v.registered) IntegrateView<false, true>(v, lo, voxel, trunc, behind, box, &acc);
            else IntegrateView<false, false>(v, lo, voxel, trunc, behind, box, &acc);
          }
        };
        auto free_space = [&](const SubBox& box) {
          for (int k = box.k0; k < box.k0 + box.side; ++k)
            for (int j = box.j0; j < box.j0 + box.side; ++j) {
              const int row = box.i0 + kBlockSide * j + kBlockSide * kBlockSide * k;
              for (int i = 0; i < box.side; ++i) {
                acc.tsdf[row + i] += 1.0f;
                acc.weight[row + i] += 1.0f;
              }
            }
        };
        if (v.distorted) {  // projected corners do not bound a distorted image region
          ++s.thread_block_views[static_cast<size_t>(thread)];
          project(SubBox{});
          continue;
        }
        lattice.Project(v, lo, voxel);
        const BlockView kind = ClassifyFootprint(v, lattice.Box(0, 0, 0, 2), trunc);
        if (kind == BlockView::kSkip) {
          ++s.thread_skipped[static_cast<size_t>(thread)];
          continue;
        }
        if (kind == BlockView::kFreeSpace) {
          ++s.thread_free[static_cast<size_t>(thread)];
          free_space(SubBox{});
          continue;
        }
        ++s.thread_block_views[static_cast<size_t>(thread)];
        // Partly in the band: the same test on each 4³ sub-block, so only
        // sub-blocks near the observed surface are projected voxel by voxel.
        constexpr int kSub = kBlockSide / 2;
        for (int c = 0; c < 2; ++c)
          for (int bb = 0; bb < 2; ++bb)
            for (int a2 = 0; a2 < 2; ++a2) {
              const SubBox box{kSub * a2, kSub * bb, kSub * c, kSub};
              const BlockView sub = ClassifyFootprint(v, lattice.Box(a2, bb, c, 1), trunc);
              if (sub == BlockView::kSkip) continue;
              if (sub == BlockView::kFreeSpace) {
                free_space(box);
              } else {
                ++s.thread_subs[static_cast<size_t>(thread)];
                project(box);
              }
            }
      }
      // Merge into the stored running averages: branch-free so the compiler
      // vectorises it; colour only where this frame saw the voxel in the band.
      VoxelBlock& vb = blocks_.block(b);
      // A block allocated this frame holds stale memory: old weight, tsdf
      // and colour are taken as 0 (what Clear() would have written).
      const bool fresh = s.fresh[static_cast<size_t>(b)] != 0;
      s.fresh[static_cast<size_t>(b)] = 0;
      if (fresh) {
        std::memset(vb.r, 0, sizeof(vb.r));
        std::memset(vb.g, 0, sizeof(vb.g));
        std::memset(vb.b, 0, sizeof(vb.b));
      }
      int has_neg = 0, has_pos = 0, has_band = 0;
#if defined(__SSE2__)
      {
        const __m128 zero = _mm_setzero_ps(), one = _mm_set1_ps(1.0f), band = _mm_set1_ps(kTsdfBandLimit);
        __m128 neg = zero, pos = zero, in_band = zero;
        for (int i = 0; i < kBlockVoxels; i += 4) {
          const __m128 w_new = _mm_load_ps(acc.weight + i);
          const __m128 w_old = fresh ? zero : _mm_load_ps(vb.weight + i);
          const __m128 t_old = fresh ? zero : _mm_load_ps(vb.tsdf + i);
          const __m128 w = _mm_add_ps(w_old, w_new);
          const __m128 seen = _mm_cmpgt_ps(w_new, zero);
          const __m128 denom = _mm_or_ps(_mm_and_ps(seen, w), _mm_andnot_ps(seen, one));
          const __m128 merged = _mm_mul_ps(_mm_add_ps(_mm_mul_ps(t_old, w_old), _mm_load_ps(acc.tsdf + i)), _mm_div_ps(one, denom));
          const __m128 t = _mm_or_ps(_mm_and_ps(seen, merged), _mm_andnot_ps(seen, t_old));
          _mm_store_ps(vb.tsdf + i, t);
          _mm_store_ps(vb.weight + i, w);
          const __m128 observed = _mm_cmpgt_ps(w, zero);
          const __m128 nonneg = _mm_and_ps(observed, _mm_cmpge_ps(t, zero));
          neg = _mm_or_ps(neg, _mm_and_ps(observed, _mm_cmplt_ps(t, zero)));
          pos = _mm_or_ps(pos, nonneg);
          in_band = _mm_or_ps(in_band, _mm_and_ps(nonneg, _mm_cmplt_ps(t, band)));
        }
        has_neg = _mm_movemask_ps(neg);
        has_pos = _mm_movemask_ps(pos);
        has_band = _mm_movemask_ps(in_band);
      }
#else
      for (int i = 0; i < kBlockVoxels; ++i) {
        const float w_new = acc.weight[i];
        const float w_old = fresh ? 0.0f : vb.weight[i];
        const float t_old = fresh ? 0.0f : vb.tsdf[i];
        const float w = w_old + w_new;
        const float merged = (t_old * w_old + acc.tsdf[i]) * (1.0f / (w_new > 0 ? w : 1.0f));
        const float t = w_new > 0 ? merged : t_old;
        vb.tsdf[i] = t;
        vb.weight[i] = w;
        const int observed = w > 0;
        has_neg |= observed & (t < 0);
        has_pos |= observed & (t >= 0);
        has_band |= observed & (t >= 0) & (t < kTsdfBandLimit);
      }
#endif
#if defined(__SSE2__)
      // Colour, four voxels at a time: the scalar loop below in the same
      // float operations (bit-identical), old colour kept where this frame
      // added none.
      if (with_color) {
        const __m128 zero = _mm_setzero_ps(), one = _mm_set1_ps(1.0f), half = _mm_set1_ps(0.5f);
        const __m128i zero_i = _mm_setzero_si128();
        uint8_t* channels[3] = {vb.r, vb.g, vb.b};
        const float* sums[3] = {acc.r, acc.g, acc.b};
        for (int i = 0; i < kBlockVoxels; i += 4) {
          const __m128 cw = _mm_load_ps(acc.color_weight + i);
          const __m128 has = _mm_cmpgt_ps(cw, zero);
          if (_mm_movemask_ps(has) == 0) continue;
          const __m128 w_new = _mm_load_ps(acc.weight + i);
          const __m128 w = _mm_load_ps(vb.weight + i);
          const __m128 w_old = _mm_sub_ps(w, w_new);
          const __m128 inv = _mm_div_ps(one, w);
          const __m128 sc = _mm_div_ps(w_new, cw);
          const __m128i keep = _mm_castps_si128(has);
          for (int ch = 0; ch < 3; ++ch) {
            int32_t old_bytes;
            std::memcpy(&old_bytes, channels[ch] + i, 4);
            const __m128i old_i = _mm_unpacklo_epi16(_mm_unpacklo_epi8(_mm_cvtsi32_si128(old_bytes), zero_i), zero_i);
            const __m128 old_f = _mm_cvtepi32_ps(old_i);
            const __m128 v = _mm_add_ps(
                _mm_mul_ps(_mm_add_ps(_mm_mul_ps(old_f, w_old), _mm_mul_ps(_mm_load_ps(sums[ch] + i), sc)), inv), half);
            const __m128i nv = _mm_cvttps_epi32(v);
            const __m128i merged = _mm_or_si128(_mm_and_si128(keep, nv), _mm_andnot_si128(keep, old_i));
            const __m128i packed = _mm_packus_epi16(_mm_packs_epi32(merged, zero_i), zero_i);
            const int32_t out_bytes = _mm_cvtsi128_si32(packed);
            std::memcpy(channels[ch] + i, &out_bytes, 4);
          }
        }
      }
#else
      for (int i = 0; i < kBlockVoxels && with_color; ++i) {
        if (!(acc.color_weight[i] > 0)) continue;
        // This frame's mean colour, with the frame's weight; an unobserved
        // old colour (w_old = 0) is simply replaced.
        const float w_new = acc.weight[i];
        const float w = vb.weight[i];
        const float w_old = w - w_new;
        const float inv = 1.0f / w;
        const float s = w_new / acc.color_weight[i];
        vb.r[i] = static_cast<uint8_t>((vb.r[i] * w_old + acc.r[i] * s) * inv + 0.5f);
        vb.g[i] = static_cast<uint8_t>((vb.g[i] * w_old + acc.g[i] * s) * inv + 0.5f);
        vb.b[i] = static_cast<uint8_t>((vb.b[i] * w_old + acc.b[i] * s) * inv + 0.5f);
      }
#endif
      blocks_.set_flags(b, BlockFlagsOf(has_neg, has_pos, has_band));
    }
  });
  const auto t3 = std::chrono::steady_clock::now();
  stats_.prepare_ms = std::chrono::duration<double, std::milli>(t1 - t0).count();
  stats_.allocate_ms = std::chrono::duration<double, std::milli>(t2 - t1).count();
  stats_.integrate_ms = std::chrono::duration<double, std::milli>(t3 - t2).count();
  for (int t = 0; t < threads; ++t) {
    stats_.block_views += s.thread_block_views[static_cast<size_t>(t)];
    stats_.block_views_skipped += s.thread_skipped[static_cast<size_t>(t)];
    stats_.block_views_free += s.thread_free[static_cast<size_t>(t)];
    stats_.sub_blocks_projected += s.thread_subs[static_cast<size_t>(t)];
  }
  return OkStatus();
}

}  // namespace holo
