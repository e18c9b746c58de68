#include "server/temporal/temporal_fusion.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <string>

#include <Eigen/LU>

#include "common/worker_pool.h"

namespace holo {

using Eigen::Matrix3f;
using Eigen::Vector3f;

namespace {

double MsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

int FloorDiv8(int64_t v) { return static_cast<int>(v >= 0 ? v / 8 : -((-v + 7) / 8)); }

// Calls `visit(gi, block, li)` for every voxel of the dense box of `nx` × `ny`
// × `nz` voxels at (`x0`, `y0`, `z0`) (voxel coordinates) that lies in an
// allocated block of `blocks`: `gi` is the voxel's row-major index in the
// box, `li` its index in `block`. One block lookup per block touched.
template <typename Visit>
void ForEachStoredVoxel(const VoxelBlockMap& blocks, int64_t x0, int64_t y0, int64_t z0, int64_t nx, int64_t ny,
                        int64_t nz, Visit&& visit) {
  for (int bz = FloorDiv8(z0); bz <= FloorDiv8(z0 + nz - 1); ++bz)
    for (int by = FloorDiv8(y0); by <= FloorDiv8(y0 + ny - 1); ++by)
      for (int bx = FloorDiv8(x0); bx <= FloorDiv8(x0 + nx - 1); ++bx) {
        if (!BlockCoordInRange(bx, by, bz)) continue;
        const int32_t bi = blocks.Find(BlockCoord{bx, by, bz});
        if (bi == VoxelBlockMap::kNotFound) continue;
        const VoxelBlock& blk = blocks.block(bi);
        const int64_t xa = std::max<int64_t>(x0, 8 * int64_t{bx}), xb = std::min<int64_t>(x0 + nx, 8 * int64_t{bx} + 8);
        const int64_t ya = std::max<int64_t>(y0, 8 * int64_t{by}), yb = std::min<int64_t>(y0 + ny, 8 * int64_t{by} + 8);
        const int64_t za = std::max<int64_t>(z0, 8 * int64_t{bz}), zb = std::min<int64_t>(z0 + nz, 8 * int64_t{bz} + 8);
        for (int64_t z = za; z < zb; ++z)
          for (int64_t y = ya; y < yb; ++y)
            for (int64_t x = xa; x < xb; ++x) {
              const int li = static_cast<int>((x - 8 * int64_t{bx}) + 8 * (y - 8 * int64_t{by}) + 64 * (z - 8 * int64_t{bz}));
              visit(static_cast<size_t>(((z - z0) * ny + (y - y0)) * nx + (x - x0)), blk, li);
            }
      }
}

}  // namespace

Status TemporalFusionOptions::Check() const {
  HOLO_RETURN_IF_ERROR(tsdf.Check());
  HOLO_RETURN_IF_ERROR(cleanup.Check());
  HOLO_RETURN_IF_ERROR(graph.Check());
  HOLO_RETURN_IF_ERROR(tracker.Check());
  HOLO_RETURN_IF_ERROR(features.Check());
  if (!(max_weight >= 1.0f && max_weight <= 1e6f))
    return InvalidArgument("max_weight must be in [1, 1e6], got " + std::to_string(max_weight));
  if (track_points < 16 || track_points > 10000000)
    return InvalidArgument("track_points must be in [16, 1e7], got " + std::to_string(track_points));
  if (!(lost_node_fraction > 0 && lost_node_fraction <= 1))
    return InvalidArgument("lost_node_fraction must be in (0, 1], got " + std::to_string(lost_node_fraction));
  if (!(min_track_weight >= 0 && min_track_weight <= 1e6f))
    return InvalidArgument("min_track_weight must be in [0, 1e6], got " + std::to_string(min_track_weight));
  if (!(min_points_per_node >= 0 && min_points_per_node <= 1000))
    return InvalidArgument("min_points_per_node must be in [0, 1000], got " + std::to_string(min_points_per_node));
  if (track_normal_radius_voxels < 0 || track_normal_radius_voxels > 8)
    return InvalidArgument("track_normal_radius_voxels must be in [0, 8], got " +
                           std::to_string(track_normal_radius_voxels));
  if (!(snap_still_m >= 0 && snap_still_m < 1))
    return InvalidArgument("snap_still_m must be in [0, 1), got " + std::to_string(snap_still_m));
  if (!(lost_min_associated >= 0 && lost_min_associated <= 1))
    return InvalidArgument("lost_min_associated must be in [0, 1], got " + std::to_string(lost_min_associated));
  if (max_lost_frames < 0 || max_lost_frames > 1000)
    return InvalidArgument("max_lost_frames must be in [0, 1000], got " + std::to_string(max_lost_frames));
  return OkStatus();
}

struct TemporalFusion::Impl {
  explicit Impl(int threads) : pool(threads) {}
  WorkerPool pool;
  struct Src {
    bool keep = false;
    bool reset = false;
    Matrix3f m, minv;
    Vector3f c, cinv, warped_center;
    std::vector<BlockCoord> targets;  // live blocks it covers
  };
  std::vector<Src> src;
  std::vector<uint8_t> near_surface;  // per reference block: 2 holds surface, 1 next to it
  // Per-thread dense copy of the reference around one live block.
  struct Gather {
    std::vector<float> tsdf, weight;
    std::vector<std::array<uint8_t, 3>> rgb;
  };
  std::vector<Gather> gather;
  struct Dst {
    Matrix3f minv;
    Vector3f cinv;
    float best = INFINITY;
    bool outside_hull = false;
  };
  std::vector<Dst> dst;
  struct Sil {
    bool usable = false;
    CameraModel camera;
    Pose camera_from_world = Pose::Identity();
    const float* dt = nullptr;  // the tracker's silhouette distance (pixels)
    int width = 0, height = 0;
  };
  std::vector<Sil> sil;
};

TemporalFusion::TemporalFusion(TemporalFusionOptions options) : options_(std::move(options)) {}
TemporalFusion::~TemporalFusion() = default;

StatusOr<std::unique_ptr<TemporalFusion>> TemporalFusion::Create(TemporalFusionOptions options) {
  HOLO_RETURN_IF_ERROR(options.Check());
  std::unique_ptr<TemporalFusion> f(new TemporalFusion(options));
  f->reference_ = std::make_unique<TsdfVolume>(options.tsdf);
  f->live_ = std::make_unique<TsdfVolume>(options.tsdf);
  f->tracker_ = std::make_unique<NonrigidTracker>(options.tracker);
  f->impl_ = std::make_unique<Impl>(options.tsdf.threads);
  return f;
}

void TemporalFusion::Reset() {
  has_reference_ = false;
  prev_fused_ = false;
  if (matcher_) matcher_->Reset();
  prev_node_pos_.clear();
  prev_node_disp_.clear();
  lost_frames_ = 0;
  reference_->Reset();
  reference_mesh_.Clear();
}

Status TemporalFusion::FusePerFrame(const Rig& rig, const RgbdFrameSet& frames, TsdfVolume* volume, Mesh* out,
                                    TemporalFrameStats* stats) {
  auto t0 = std::chrono::steady_clock::now();
  volume->Reset();
  HOLO_RETURN_IF_ERROR(volume->Integrate(rig, frames));
  stats->fuse_ms += MsSince(t0);
  t0 = std::chrono::steady_clock::now();
  volume->ExtractMesh(out);
  HOLO_RETURN_IF_ERROR(CleanupMesh(options_.cleanup, out));
  stats->mesh_ms += MsSince(t0);
  return OkStatus();
}

void TemporalFusion::WarpReference(const Rig& rig, const RgbdFrameSet& /*frames*/, const TrackResult& track,
                                   TemporalFrameStats* stats) {
  Impl& m = *impl_;
  const VoxelBlockMap& src = reference_->blocks();
  VoxelBlockMap& dst = live_->mutable_blocks();
  live_->Reset();
  const float vs = options_.tsdf.voxel_size;
  const float bs = vs * kBlockSide;
  const int nsrc = static_cast<int>(src.size());
  m.src.resize(static_cast<size_t>(nsrc));

  // Silhouettes (distance to the nearest foreground pixel) for the hull test.
  m.sil.resize(rig.pods.size());
  for (size_t i = 0; i < rig.pods.size(); ++i) {
    Impl::Sil& s = m.sil[i];
    s.usable = false;
    if (!options_.hull_carving) continue;
    int w = 0, h = 0;
    const float* dt = tracker_->SilhouetteDistance(i, &w, &h);
    if (dt == nullptr) continue;  // no silhouette: this pod says nothing
    s.dt = dt;
    s.width = w;
    s.height = h;
    s.camera = rig.pods[i].DepthCamera();
    s.camera_from_world = s.camera.world_from_camera.inverse();
    s.usable = true;
  }

  // Only blocks holding the cleaned reference surface and their neighbours
  // are carried: junk the clean-up removed (flying-pixel blobs) must not
  // accumulate over frames.
  m.near_surface.assign(static_cast<size_t>(nsrc), 0);
  {
    BlockCoord last{INT32_MIN, 0, 0};
    for (const Vector3f& p : reference_mesh_.positions) {
      const Vector3f q = p / bs;
      const BlockCoord c{static_cast<int32_t>(std::floor(q.x())), static_cast<int32_t>(std::floor(q.y())),
                         static_cast<int32_t>(std::floor(q.z()))};
      if (c == last) continue;
      last = c;
      if (!BlockCoordInRange(c.x, c.y, c.z)) continue;
      const int32_t i = src.Find(c);
      if (i != VoxelBlockMap::kNotFound) m.near_surface[static_cast<size_t>(i)] = 2;
    }
    for (int b = 0; b < nsrc; ++b) {
      if (m.near_surface[static_cast<size_t>(b)] != 2) continue;
      const BlockCoord c = src.coord(b);
      for (int dz = -1; dz <= 1; ++dz)
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            const int32_t i = src.Find(BlockCoord{c.x + dx, c.y + dy, c.z + dz});
            if (i != VoxelBlockMap::kNotFound && m.near_surface[static_cast<size_t>(i)] == 0)
              m.near_surface[static_cast<size_t>(i)] = 1;
          }
    }
  }

  // A: per reference block, its warp (blended node transform at the centre).
  m.pool.ParallelFor(nsrc, [&](int b) {
    Impl::Src& s = m.src[static_cast<size_t>(b)];
    s.keep = false;
    s.reset = false;
    if (m.near_surface[static_cast<size_t>(b)] == 0) return;
    const uint8_t fl = src.flags(b);
    if (!(fl & (kBlockHasNegative | kBlockHasPositiveInBand))) return;  // free space only: nothing to carry
    const BlockCoord bc = src.coord(b);
    const Vector3f centre = (Vector3f(bc.x, bc.y, bc.z) * kBlockSide + Vector3f::Constant(3.5f)) * vs;
    const SkinWeights skin = graph_.Skin(centre);
    if (!skin.valid()) return;
    if (options_.reset_failed_regions && !track.nodes.empty()) {
      float failed = 0;
      for (int i = 0; i < kSkinNodes && skin.node[static_cast<size_t>(i)] >= 0; ++i)
        if (track.nodes[static_cast<size_t>(skin.node[static_cast<size_t>(i)])].failed)
          failed += skin.weight[static_cast<size_t>(i)];
      if (failed > 0.5f) {
        s.reset = true;
        return;
      }
    }
    graph_.BlendedTransform(skin, &s.m, &s.c);
    const float det = s.m.determinant();
    if (!(det > 0.2f && det < 5.0f)) return;
    s.minv = s.m.inverse();
    s.cinv = -s.minv * s.c;
    s.warped_center = s.m * centre + s.c;
    // Live blocks to allocate: those covered by the warped 4³ sub-blocks
    // that hold observed non-free-space voxels.
    s.targets.clear();
    const VoxelBlock& vb = src.block(b);
    for (int sb = 0; sb < 8; ++sb) {
      const int ox = 4 * (sb & 1), oy = 4 * ((sb >> 1) & 1), oz = 4 * ((sb >> 2) & 1);
      bool occupied = false;
      for (int k = oz; k < oz + 4 && !occupied; ++k)
        for (int j = oy; j < oy + 4 && !occupied; ++j)
          for (int i = ox; i < ox + 4; ++i) {
            const int vi = i + 8 * j + 64 * k;
            if (vb.weight[vi] > 0 && vb.tsdf[vi] < 0.999f) {
              occupied = true;
              break;
            }
          }
      if (!occupied) continue;
      Vector3f lo = Vector3f::Constant(INFINITY), hi = Vector3f::Constant(-INFINITY);
      for (int c = 0; c < 8; ++c) {
        const Vector3f corner = (Vector3f(bc.x, bc.y, bc.z) * kBlockSide +
                                 Vector3f(ox + 4 * (c & 1), oy + 4 * ((c >> 1) & 1), oz + 4 * ((c >> 2) & 1)) -
                                 Vector3f::Constant(0.5f)) * vs;
        const Vector3f w = s.m * corner + s.c;
        lo = lo.cwiseMin(w);
        hi = hi.cwiseMax(w);
      }
      std::array<int, 3> l{}, h{};
      for (int a = 0; a < 3; ++a) {
        l[a] = static_cast<int>(std::floor((lo[a] + 0.5f * vs) / bs));
        h[a] = static_cast<int>(std::floor((hi[a] + 0.5f * vs) / bs));
        if (h[a] - l[a] > 2 || !BlockCoordInRange(l[a], l[a], l[a]) || !BlockCoordInRange(h[a], h[a], h[a])) return;
      }
      for (int z = l[2]; z <= h[2]; ++z)
        for (int y = l[1]; y <= h[1]; ++y)
          for (int x = l[0]; x <= h[0]; ++x) {
            const BlockCoord t{x, y, z};
            if (std::find(s.targets.begin(), s.targets.end(), t) == s.targets.end()) s.targets.push_back(t);
          }
    }
    s.keep = true;
  });

  // B: allocate the live blocks the warped reference covers; each takes the
  // inverse warp of the reference block whose warped centre is nearest.
  m.dst.clear();
  size_t reset_blocks = 0;
  for (int b = 0; b < nsrc; ++b) {
    const Impl::Src& s = m.src[static_cast<size_t>(b)];
    reset_blocks += s.reset;
    if (!s.keep) continue;
    for (const BlockCoord& t : s.targets) {
      const int32_t d = dst.FindOrAllocate(t);
      if (static_cast<size_t>(d) >= m.dst.size()) m.dst.resize(static_cast<size_t>(d) + 1);
      Impl::Dst& di = m.dst[static_cast<size_t>(d)];
      const Vector3f dc = (Vector3f(t.x, t.y, t.z) * kBlockSide + Vector3f::Constant(3.5f)) * vs;
      const float dist = (dc - s.warped_center).squaredNorm();
      if (dist < di.best) {
        di.best = dist;
        di.minv = s.minv;
        di.cinv = s.cinv;
      }
    }
  }
  stats->reset_blocks = reset_blocks;
  stats->region_reset = reset_blocks > 0;

  // C: fill every live block by sampling the reference (trilinear) at the
  // inverse-warped voxel centres; drop blocks outside a silhouette.
  const int ndst = static_cast<int>(dst.size());
  std::atomic<size_t> hull_dropped{0}, carried{0};
  const float radius = 0.5f * bs * 0.87f;  // of a 4³ sub-block
  const float cap = options_.max_weight;
  m.gather.resize(static_cast<size_t>(m.pool.num_threads()));
  m.pool.Run(ndst, [&](int d, int thread) {
    VoxelBlock& out = dst.block(d);
    const BlockCoord bc = dst.coord(d);
    const Impl::Dst& di = m.dst[static_cast<size_t>(d)];
    // Visual hull per 4³ sub-block: a sub-block whose centre projects
    // farther outside a pod's silhouette than its own radius is free space.
    bool sub_out[8];
    int num_out = 0;
    for (int sb = 0; sb < 8; ++sb) {
      sub_out[sb] = false;
      const Vector3f centre = (Vector3f(bc.x, bc.y, bc.z) * kBlockSide +
                               Vector3f(4 * (sb & 1) + 1.5f, 4 * ((sb >> 1) & 1) + 1.5f, 4 * ((sb >> 2) & 1) + 1.5f)) * vs;
      for (const Impl::Sil& s : m.sil) {
        if (!s.usable) continue;
        const Vector3f pc = s.camera_from_world * centre;
        Eigen::Vector2f px;
        if (pc.z() < 0.1f || !s.camera.ProjectCamera(pc, &px)) continue;
        const int u = static_cast<int>(std::lround(px.x())), v = static_cast<int>(std::lround(px.y()));
        if (u < 0 || v < 0 || u >= s.width || v >= s.height) continue;
        const float r_px = radius * static_cast<float>(s.camera.intrinsics.fx) / pc.z();
        if (s.dt[static_cast<size_t>(v) * s.width + u] > r_px + 2.0f) {
          sub_out[sb] = true;
          ++num_out;
          break;
        }
      }
    }
    if (num_out == 8) {
      ++hull_dropped;
      for (int vi = 0; vi < kBlockVoxels; ++vi) {
        out.weight[vi] = 0;
        out.tsdf[vi] = 1;
      }
      dst.set_flags(d, 0);
      return;  // all voxels stay unobserved (weight 0)
    }
    // Dense copy of the reference voxels the block's inverse warp reaches.
    Vector3f lo = Vector3f::Constant(INFINITY), hi = Vector3f::Constant(-INFINITY);
    for (int c = 0; c < 8; ++c) {
      const Vector3f y = (Vector3f(bc.x, bc.y, bc.z) * kBlockSide +
                          Vector3f(7 * (c & 1), 7 * ((c >> 1) & 1), 7 * ((c >> 2) & 1))) * vs;
      const Vector3f x = (di.minv * y + di.cinv) / vs;
      lo = lo.cwiseMin(x);
      hi = hi.cwiseMax(x);
    }
    const int64_t gx0 = static_cast<int64_t>(std::floor(lo.x())), gy0 = static_cast<int64_t>(std::floor(lo.y())),
                  gz0 = static_cast<int64_t>(std::floor(lo.z()));
    const int nx = static_cast<int>(std::floor(hi.x())) - static_cast<int>(gx0) + 2;
    const int ny = static_cast<int>(std::floor(hi.y())) - static_cast<int>(gy0) + 2;
    const int nz = static_cast<int>(std::floor(hi.z())) - static_cast<int>(gz0) + 2;
    uint8_t flags = 0;
    bool any = false;
    for (int vi = 0; vi < kBlockVoxels; ++vi) {
      out.weight[vi] = 0;
      out.tsdf[vi] = 1;
      out.r[vi] = out.g[vi] = out.b[vi] = 0;
    }
    if (nx <= 0 || ny <= 0 || nz <= 0 || nx > 24 || ny > 24 || nz > 24) {
      dst.set_flags(d, 0);
      return;
    }
    Impl::Gather& g = m.gather[static_cast<size_t>(thread)];
    const size_t nvox = static_cast<size_t>(nx) * ny * nz;
    g.tsdf.assign(nvox, 1.0f);
    g.weight.assign(nvox, 0.0f);
    g.rgb.resize(nvox);
    ForEachStoredVoxel(src, gx0, gy0, gz0, nx, ny, nz, [&g](size_t gi, const VoxelBlock& sb, int li) {
      g.tsdf[gi] = sb.tsdf[li];
      g.weight[gi] = sb.weight[li];
      g.rgb[gi] = {sb.r[li], sb.g[li], sb.b[li]};
    });
    const Vector3f step_x = di.minv.col(0), step_y = di.minv.col(1), step_z = di.minv.col(2);
    const Vector3f origin = di.minv * (Vector3f(bc.x, bc.y, bc.z) * (kBlockSide * vs)) / vs + di.cinv / vs -
                            Vector3f(static_cast<float>(gx0), static_cast<float>(gy0), static_cast<float>(gz0));
    const size_t sy = static_cast<size_t>(nx), sz = static_cast<size_t>(nx) * ny;
    for (int k = 0; k < kBlockSide; ++k)
      for (int j = 0; j < kBlockSide; ++j)
        for (int i = 0; i < kBlockSide; ++i) {
          const int vi = i + 8 * j + 64 * k;
          if (sub_out[(i >> 2) + 2 * (j >> 2) + 4 * (k >> 2)]) continue;
          const Vector3f x = origin + step_x * static_cast<float>(i) + step_y * static_cast<float>(j) +
                             step_z * static_cast<float>(k);
          const float fx = std::floor(x.x()), fy = std::floor(x.y()), fz = std::floor(x.z());
          const int ix = static_cast<int>(fx), iy = static_cast<int>(fy), iz = static_cast<int>(fz);
          if (ix < 0 || iy < 0 || iz < 0 || ix + 1 >= nx || iy + 1 >= ny || iz + 1 >= nz) continue;
          const float ax = x.x() - fx, ay = x.y() - fy, az = x.z() - fz;
          const size_t base = static_cast<size_t>(ix) + sy * iy + sz * iz;
          float sw = 0, st = 0, swt = 0, best = -1;
          size_t bi = base;
          for (int c = 0; c < 8; ++c) {
            const int dx = c & 1, dy = (c >> 1) & 1, dz = (c >> 2) & 1;
            const size_t gi = base + dx + sy * dy + sz * dz;
            const float wv = g.weight[gi];
            if (wv <= 0) continue;
            const float a = (dx ? ax : 1 - ax) * (dy ? ay : 1 - ay) * (dz ? az : 1 - az);
            sw += a;
            st += a * g.tsdf[gi];
            swt += a * wv;
            if (a > best) {
              best = a;
              bi = gi;
            }
          }
          if (sw < 0.5f) continue;
          const float t = st / sw;
          out.tsdf[vi] = t;
          out.weight[vi] = std::min(cap, swt / sw);
          out.r[vi] = g.rgb[bi][0];
          out.g[vi] = g.rgb[bi][1];
          out.b[vi] = g.rgb[bi][2];
          any = true;
          if (t < 0) flags |= kBlockHasNegative;
          else {
            flags |= kBlockHasPositive;
            if (t < 0.999f) flags |= kBlockHasPositiveInBand;
          }
        }
    dst.set_flags(d, flags);
    if (any) ++carried;
  });
  stats->hull_blocks = hull_dropped.load();
  stats->carried_blocks = carried.load();
}

void TemporalFusion::SmoothTrackNormals() {
  const int r = options_.track_normal_radius_voxels;
  const int side = 2 * r + 1;
  const float vs = options_.tsdf.voxel_size;
  const VoxelBlockMap& blocks = reference_->blocks();
  impl_->pool.ParallelFor(static_cast<int>((points_.size() + 255) / 256), [&](int c) {
    // The (2r+1)³ voxels around a point, copied once (a block lookup per
    // block touched instead of one per voxel read).
    std::vector<float> t(static_cast<size_t>(side) * side * side), w(t.size());
    const size_t i0 = static_cast<size_t>(c) * 256, i1 = std::min(points_.size(), i0 + 256);
    for (size_t i = i0; i < i1; ++i) {
      const Vector3f q = points_[i] / vs;
      const int64_t x0 = std::lround(q.x()) - r, y0 = std::lround(q.y()) - r, z0 = std::lround(q.z()) - r;
      std::fill(w.begin(), w.end(), 0.0f);
      ForEachStoredVoxel(blocks, x0, y0, z0, side, side, side, [&t, &w](size_t gi, const VoxelBlock& blk, int li) {
        t[gi] = blk.tsdf[li];
        w[gi] = blk.weight[li];
      });
      // Central differences between the patch's opposite faces (r voxels
      // either side of the centre), summed over each face: a box-filtered
      // gradient. Every face voxel must be observed.
      const size_t sy = static_cast<size_t>(side), sz = sy * sy, last = static_cast<size_t>(side - 1);
      Vector3f g = Vector3f::Zero();
      bool ok = true;
      auto diff = [&](size_t hi, size_t lo) {
        ok = ok && w[hi] > 0 && w[lo] > 0;
        return t[hi] - t[lo];
      };
      for (size_t u = 0; u < sy; ++u)
        for (size_t v = 0; v < sy; ++v) g.x() += diff(last + sy * u + sz * v, sy * u + sz * v);
      for (size_t u = 0; u < sy; ++u)
        for (size_t v = 0; v < sy; ++v) g.y() += diff(v + sy * last + sz * u, v + sz * u);
      for (size_t u = 0; u < sy; ++u)
        for (size_t v = 0; v < sy; ++v) g.z() += diff(u + sy * v + sz * last, u + sy * v);
      if (!ok) continue;  // keep the mesh normal
      const float len = g.norm();
      if (!(len > 1e-6f)) continue;
      const Vector3f n = g / len;
      // A thin part or a nearby surface can flip the box-filtered gradient.
      if (n.dot(normals_[i]) > 0.5f) normals_[i] = n;
    }
  });
}

Status TemporalFusion::Process(const Rig& rig, const RgbdFrameSet& frames, Mesh* out, TemporalFrameStats* stats) {
  const auto t_start = std::chrono::steady_clock::now();
  *stats = TemporalFrameStats();
  if (frames.frames.size() != rig.pods.size())
    return InvalidArgument("frame set has " + std::to_string(frames.frames.size()) + " pods but the rig has " +
                           std::to_string(rig.pods.size()));
  // Colour features of this frame, matched to the previous frame's. They
  // are used only if the previous frame was fused (its observation is then
  // what the reference shows).
  // Temporal mode with the sparse term on (by resolution: the rig decides).
  const bool use_features = options_.temporal && options_.tracker.SparseOn(rig);
  if (use_features && matcher_ == nullptr) matcher_ = std::make_unique<FeatureMatcher>(options_.features);
  pairs_.clear();
  if (use_features) {
    const auto tf = std::chrono::steady_clock::now();
    HOLO_RETURN_IF_ERROR(matcher_->Match(rig, frames, &pairs_));
    if (!prev_fused_) pairs_.clear();
    stats->features_ms = MsSince(tf);
    stats->feature_pairs = pairs_.size();
  }
  prev_fused_ = false;
  if (!options_.temporal || !has_reference_) {
    HOLO_RETURN_IF_ERROR(FusePerFrame(rig, frames, live_.get(), out, stats));
    prev_fused_ = true;
    if (options_.temporal) {
      std::swap(reference_, live_);
      reference_mesh_ = *out;
      has_reference_ = !out->empty();
    }
    stats->total_ms = MsSince(t_start);
    return OkStatus();
  }

  // Track the reference surface into this frame.
  auto t0 = std::chrono::steady_clock::now();
  const size_t nv = reference_mesh_.positions.size();
  const bool has_normals = reference_mesh_.normals.size() == nv;
  const float vs = options_.tsdf.voxel_size;
  auto sample = [&](size_t count) {
    points_.clear();
    normals_.clear();
    const size_t stride = std::max<size_t>(1, nv / std::max<size_t>(1, count));
    for (size_t i = 0; i < nv; i += stride) {
      const Vector3f n = has_normals ? reference_mesh_.normals[i] : Vector3f::Zero();
      const float len = n.norm();
      if (!(len > 1e-6f)) continue;
      const Vector3f& p = reference_mesh_.positions[i];
      if (options_.min_track_weight > 0) {
        float t, w;
        reference_->VoxelAt(std::lround(p.x() / vs), std::lround(p.y() / vs), std::lround(p.z() / vs), &t, &w);
        if (w < options_.min_track_weight) continue;
      }
      points_.push_back(p);
      normals_.push_back(n / len);
    }
  };
  sample(static_cast<size_t>(options_.track_points));
  HOLO_RETURN_IF_ERROR(graph_.Build(points_, options_.graph));
  if (options_.min_points_per_node > 0) {
    const size_t want = static_cast<size_t>(options_.min_points_per_node * static_cast<float>(graph_.num_nodes()));
    if (want > points_.size() * 11 / 10) {
      sample(want);
      HOLO_RETURN_IF_ERROR(graph_.Build(points_, options_.graph));
    }
  }
  if (options_.track_normal_radius_voxels > 0) SmoothTrackNormals();
  if (options_.predict_motion && !prev_node_pos_.empty()) {
    const float max_d = 2.0f * options_.graph.node_spacing_m;
    for (size_t k = 0; k < graph_.num_nodes(); ++k) {
      const Vector3f& g = graph_.position(static_cast<int>(k));
      float best = max_d * max_d;
      int bi = -1;
      for (size_t j = 0; j < prev_node_pos_.size(); ++j) {
        const float d = (prev_node_pos_[j] - g).squaredNorm();
        if (d < best) {
          best = d;
          bi = static_cast<int>(j);
        }
      }
      if (bi >= 0) graph_.translation(static_cast<int>(k)) = prev_node_disp_[static_cast<size_t>(bi)];
    }
  }
  HOLO_RETURN_IF_ERROR(tracker_->Track(rig, frames, points_, normals_, &graph_, &stats->track,
                                       use_features ? &pairs_ : nullptr));
  stats->tracked = true;
  stats->nodes = static_cast<int>(graph_.num_nodes());
  stats->failed_nodes = stats->track.failed_nodes;
  stats->track_ms = MsSince(t0) + stats->features_ms;

  const bool lost =
      graph_.num_nodes() == 0 ||
      stats->failed_nodes > options_.lost_node_fraction * static_cast<float>(graph_.num_nodes()) ||
      static_cast<float>(stats->track.associated_points) <
          options_.lost_min_associated * static_cast<float>(stats->track.num_points);
  if (lost) {
    ++lost_frames_;
    prev_node_pos_.clear();
    prev_node_disp_.clear();
    if (lost_frames_ <= options_.max_lost_frames) {
      *out = reference_mesh_;  // hold the picture; track the reference into the next frame
      stats->lost = true;
      stats->total_ms = MsSince(t_start);
      return OkStatus();
    }
    HOLO_RETURN_IF_ERROR(FusePerFrame(rig, frames, live_.get(), out, stats));
    {
      // Full reset: this frame becomes the new reference (key frame).
      std::swap(reference_, live_);
      reference_mesh_ = *out;
      has_reference_ = !out->empty();
      lost_frames_ = 0;
      stats->full_reset = true;
      prev_fused_ = true;
    }
    stats->total_ms = MsSince(t_start);
    return OkStatus();
  }
  lost_frames_ = 0;
  if (options_.snap_still_m > 0) {
    for (size_t k = 0; k < graph_.num_nodes(); ++k) {
      const int ki = static_cast<int>(k);
      if (graph_.translation(ki).norm() < options_.snap_still_m &&
          (graph_.affine(ki) - Eigen::Matrix3f::Identity()).norm() < 10.0f * options_.snap_still_m) {
        graph_.translation(ki).setZero();
        graph_.affine(ki).setIdentity();
      }
    }
  }
  prev_node_pos_.clear();
  prev_node_disp_.clear();
  for (size_t k = 0; k < graph_.num_nodes(); ++k) {
    if (stats->track.nodes[k].failed) continue;
    const int ki = static_cast<int>(k);
    prev_node_pos_.push_back(graph_.position(ki) + graph_.translation(ki));
    prev_node_disp_.push_back(graph_.translation(ki));
  }

  // Warp the reference into the live frame, fuse the observation into it.
  t0 = std::chrono::steady_clock::now();
  WarpReference(rig, frames, stats->track, stats);
  stats->warp_ms = MsSince(t0);
  t0 = std::chrono::steady_clock::now();
  const Status s = live_->Integrate(rig, frames);
  stats->fuse_ms = MsSince(t0);
  if (!s.ok()) {
    live_->Reset();
    return s;
  }
  t0 = std::chrono::steady_clock::now();
  live_->ExtractMesh(out);
  HOLO_RETURN_IF_ERROR(CleanupMesh(options_.cleanup, out));
  stats->mesh_ms = MsSince(t0);
  std::swap(reference_, live_);
  reference_mesh_ = *out;
  has_reference_ = !out->empty();
  prev_fused_ = true;
  stats->total_ms = MsSince(t_start);
  return OkStatus();
}

}  // namespace holo
