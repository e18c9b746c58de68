#include "server/fusion/visual_hull.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <string>

#include <opencv2/imgproc.hpp>

#include "common/clock.h"
#include "common/worker_pool.h"
#include "server/fusion/tsdf_internal.h"

namespace holo {
namespace {

// One pod's silhouette as the hull needs it: the camera (pinhole fast path,
// or the full model when the lens is distorted) and the mask's signed
// distance transform in pixels (> 0 inside the silhouette).
struct PodSilhouette {
  Eigen::Matrix3f R;  // camera from world
  Eigen::Vector3f t;
  float fx = 1, fy = 1, cx = 0, cy = 0;
  float inv_f = 1;  // 1 / mean focal length: pixels → metres at depth 1
  int width = 0, height = 0;
  bool distorted = false;
  CameraModel camera;
  cv::Mat signed_distance;  // CV_32F, width × height

  // Signed distance (metres, > 0 outside this pod's cone) of world point p,
  // or false when the pod does not see p (behind it or outside its image).
  bool Distance(const Eigen::Vector3f& p, float* d) const {
    const Eigen::Vector3f c = R * p + t;
    if (c.z() <= 0.05f) return false;
    float u, v;
    if (!distorted) {
      const float iz = 1.0f / c.z();
      u = fx * c.x() * iz + cx;
      v = fy * c.y() * iz + cy;
    } else {
      Eigen::Vector2f px;
      if (!camera.ProjectCamera(c, &px)) return false;
      u = px.x();
      v = px.y();
    }
    const int x = static_cast<int>(std::floor(u + 0.5f)), y = static_cast<int>(std::floor(v + 0.5f));
    if (x < 0 || y < 0 || x >= width || y >= height) return false;
    *d = -signed_distance.at<float>(y, x) * c.z() * inv_f;
    return true;
  }
};

}  // namespace

Status VisualHullOptions::Check() const {
  for (int a = 0; a < 3; ++a) {
    if (!std::isfinite(box_min[a]) || !std::isfinite(box_max[a]) || !(box_max[a] > box_min[a]))
      return InvalidArgument("visual hull box: max must exceed min on every axis, got min (" +
                             std::to_string(box_min.x()) + ", " + std::to_string(box_min.y()) + ", " +
                             std::to_string(box_min.z()) + ") max (" + std::to_string(box_max.x()) + ", " +
                             std::to_string(box_max.y()) + ", " + std::to_string(box_max.z()) + ")");
    if (box_max[a] - box_min[a] > 100.0f) return InvalidArgument("visual hull box is larger than 100 m");
  }
  if (min_views < 1 || min_views > 64) return InvalidArgument("min_views must be in 1..64, got " + std::to_string(min_views));
  if (threads < 0 || threads > 256) return InvalidArgument("threads must be in 0..256, got " + std::to_string(threads));
  return OkStatus();
}

struct VisualHull::Impl {
  explicit Impl(int threads) : pool(ResolveThreadCount(threads)) {}
  WorkerPool pool;
  std::vector<PodSilhouette> pods;
  std::vector<BlockCoord> near;       // blocks near the surface, this frame
  std::vector<uint8_t> near_flag;     // per candidate block (scratch)
};

VisualHull::VisualHull(VisualHullOptions options) : options_(options) {
  const Status st = options_.Check();
  HOLO_CHECK_MSG(st.ok(), st.ToString());
  impl_ = std::make_unique<Impl>(options_.threads);
}

StatusOr<std::unique_ptr<VisualHull>> VisualHull::Create(VisualHullOptions options) {
  HOLO_RETURN_IF_ERROR(options.Check());
  return std::make_unique<VisualHull>(options);
}

VisualHull::~VisualHull() = default;

Status VisualHull::Build(const Rig& rig, const RgbdFrameSet& frames, TsdfVolume* volume) {
  if (volume == nullptr) return InvalidArgument("visual hull: volume is null");
  if (rig.pods.empty()) return InvalidArgument("visual hull: the rig has no pods");
  if (frames.frames.size() != rig.pods.size())
    return InvalidArgument("visual hull: frame set has " + std::to_string(frames.frames.size()) +
                           " pods, the rig has " + std::to_string(rig.pods.size()));
  for (size_t k = 0; k < rig.pods.size(); ++k) {
    const PodCalibration& pod = rig.pods[k];
    const ImageGray8& m = frames.frames[k].mask;
    HOLO_RETURN_IF_ERROR(pod.depth.Check().WithContext("visual hull: pod " + std::to_string(k) + " intrinsics"));
    if (m.empty()) return InvalidArgument("visual hull: pod " + std::to_string(k) + " has no mask");
    if (m.width() != pod.depth.width || m.height() != pod.depth.height)
      return InvalidArgument("visual hull: pod " + std::to_string(k) + " mask is " + std::to_string(m.width()) + "x" +
                             std::to_string(m.height()) + ", its camera " + std::to_string(pod.depth.width) + "x" +
                             std::to_string(pod.depth.height));
  }
  stats_ = {};
  Impl& im = *impl_;
  const size_t num_pods = rig.pods.size();

  // 1. Cameras and signed distance transforms (per pod, in parallel).
  Stopwatch sw;
  im.pods.resize(num_pods);
  im.pool.Run(num_pods, [&](size_t k, int) {
    const PodCalibration& pod = rig.pods[k];
    PodSilhouette& s = im.pods[k];
    const Pose cam_from_world = pod.world_from_depth.inverse();
    s.R = cam_from_world.linear();
    s.t = cam_from_world.translation();
    s.fx = static_cast<float>(pod.depth.fx);
    s.fy = static_cast<float>(pod.depth.fy);
    s.cx = static_cast<float>(pod.depth.cx);
    s.cy = static_cast<float>(pod.depth.cy);
    s.inv_f = 2.0f / (s.fx + s.fy);
    s.width = pod.depth.width;
    s.height = pod.depth.height;
    s.distorted = pod.depth.HasDistortion();
    s.camera = CameraModel{pod.depth, Pose::Identity()};
    const ImageGray8& m = frames.frames[k].mask;
    // OpenCV wants a writable header; the mask is only read.
    const cv::Mat mask(m.height(), m.width(), CV_8UC1, const_cast<uint8_t*>(m.data()));
    cv::Mat fg = mask > 127, bg = mask <= 127;
    cv::Mat din, dout;
    // Distance of each foreground pixel to the nearest background pixel and
    // vice versa: inside positive, outside negative (the edge lies between).
    cv::distanceTransform(fg, din, cv::DIST_L2, cv::DIST_MASK_5);
    cv::distanceTransform(bg, dout, cv::DIST_L2, cv::DIST_MASK_5);
    s.signed_distance = din - dout;
  });
  stats_.distance_ms = sw.ElapsedMs();

  // 2. Blocks near the surface: the field at every block centre of the box.
  sw.Restart();
  volume->Reset();
  const TsdfOptions& vo = volume->options();
  const float voxel = vo.voxel_size;
  const float trunc = vo.truncation_voxels * voxel;
  const float block_m = voxel * kBlockSide;
  auto block_of = [&](float v) { return static_cast<int32_t>(std::floor(v / block_m)); };
  const int32_t bx0 = block_of(options_.box_min.x()), bx1 = block_of(options_.box_max.x());
  const int32_t by0 = block_of(options_.box_min.y()), by1 = block_of(options_.box_max.y());
  const int32_t bz0 = block_of(options_.box_min.z()), bz1 = block_of(options_.box_max.z());
  if (!BlockCoordInRange(bx0, by0, bz0) || !BlockCoordInRange(bx1, by1, bz1))
    return InvalidArgument("visual hull: the box is out of the volume's range at this voxel size");
  const int64_t nx = bx1 - bx0 + 1, ny = by1 - by0 + 1, nz = bz1 - bz0 + 1;
  const int64_t candidates = nx * ny * nz;
  if (candidates > (int64_t{1} << 24))
    return InvalidArgument("visual hull: the box holds " + std::to_string(candidates) +
                           " blocks at this voxel size (at most 16 M)");
  // The field of a point; false when fewer than min_views pods see it. A pod
  // that sees the point at least `stop` outside its silhouette settles it
  // (the rest cannot lower a maximum): free space, observed.
  const int min_views = options_.min_views;
  auto field = [&](const Eigen::Vector3f& p, float stop, float* d) {
    int views = 0;
    float dmax = -INFINITY;
    for (const PodSilhouette& s : im.pods) {
      float dp;
      if (!s.Distance(p, &dp)) continue;
      if (dp >= stop) {
        *d = dp;
        return true;
      }
      ++views;
      dmax = std::max(dmax, dp);
    }
    *d = dmax;
    return views >= min_views;
  };
  // Half the block's diagonal between voxel centres, the truncation, and a
  // factor 1.5 for the cone-distance estimate.
  const float reach = 1.5f * (0.5f * std::sqrt(3.0f) * voxel * (kBlockSide - 1) + trunc);
  im.near_flag.assign(static_cast<size_t>(candidates), 0);
  im.pool.Run(static_cast<size_t>(nz), [&](size_t zi, int) {
    const int32_t bz = bz0 + static_cast<int32_t>(zi);
    for (int32_t by = by0; by <= by1; ++by)
      for (int32_t bx = bx0; bx <= bx1; ++bx) {
        const Eigen::Vector3f centre = (Eigen::Vector3f(static_cast<float>(bx), static_cast<float>(by),
                                                        static_cast<float>(bz)) * kBlockSide +
                                        Eigen::Vector3f::Constant(0.5f * (kBlockSide - 1))) * voxel;
        float d;
        // Blocks whose centre too few pods see are left out (the hull is
        // cut where the views stop overlapping).
        if (!field(centre, reach, &d) || std::abs(d) > reach) continue;
        im.near_flag[static_cast<size_t>(((zi * ny) + (by - by0)) * nx + (bx - bx0))] = 1;
      }
  });
  stats_.blocks_tested = static_cast<size_t>(candidates);
  im.near.clear();
  for (int64_t zi = 0; zi < nz; ++zi)
    for (int64_t yi = 0; yi < ny; ++yi)
      for (int64_t xi = 0; xi < nx; ++xi)
        if (im.near_flag[static_cast<size_t>((zi * ny + yi) * nx + xi)])
          im.near.push_back(BlockCoord{static_cast<int32_t>(bx0 + xi), static_cast<int32_t>(by0 + yi),
                                       static_cast<int32_t>(bz0 + zi)});

  // 3. The field at every voxel of those blocks (allocation serial, filling in parallel).
  VoxelBlockMap& blocks = volume->mutable_blocks();
  std::vector<int32_t> index(im.near.size());
  for (size_t i = 0; i < im.near.size(); ++i) index[i] = blocks.FindOrAllocate(im.near[i], nullptr, /*clear=*/true);
  const float inv_trunc = 1.0f / trunc;
  const Eigen::Vector3f lo = options_.box_min, hi = options_.box_max;
  // Each block as eight 4³ sub-blocks: one far from the surface (its centre
  // farther than its own reach) is set whole to ±1 (or unobserved) from its
  // centre; the others voxel by voxel.
  constexpr int kSub = kBlockSide / 2;
  const float sub_reach = 1.5f * (0.5f * std::sqrt(3.0f) * voxel * (kSub - 1) + trunc);
  im.pool.Run(im.near.size(), [&](size_t i, int) {
    const BlockCoord& bc = im.near[i];
    VoxelBlock& vb = blocks.block(index[i]);
    bool has_neg = false, has_pos = false, has_band = false;
    auto set = [&](int v, bool observed, float d) {
      if (!observed) {
        vb.weight[v] = 0.0f;
        vb.tsdf[v] = 1.0f;
        return;
      }
      const float t = std::clamp(d * inv_trunc, -1.0f, 1.0f);
      vb.tsdf[v] = t;
      vb.weight[v] = 1.0f;
      has_neg |= t < 0;
      has_pos |= t >= 0;
      has_band |= t >= 0 && t < kTsdfBandLimit;
    };
    auto voxel_pos = [&](int a, int j, int k) -> Eigen::Vector3f {
      return {static_cast<float>(bc.x * kBlockSide + a) * voxel, static_cast<float>(bc.y * kBlockSide + j) * voxel,
              static_cast<float>(bc.z * kBlockSide + k) * voxel};
    };
    auto in_box = [&](const Eigen::Vector3f& p) { return (p.array() >= lo.array()).all() && (p.array() <= hi.array()).all(); };
    for (int sk = 0; sk < kBlockSide; sk += kSub)
      for (int sj = 0; sj < kBlockSide; sj += kSub)
        for (int si = 0; si < kBlockSide; si += kSub) {
          const Eigen::Vector3f centre =
              (voxel_pos(si, sj, sk) + voxel_pos(si + kSub - 1, sj + kSub - 1, sk + kSub - 1)) * 0.5f;
          float dc;
          const bool seen = field(centre, sub_reach, &dc);
          const bool whole_box = in_box(voxel_pos(si, sj, sk)) && in_box(voxel_pos(si + kSub - 1, sj + kSub - 1, sk + kSub - 1));
          const bool settled = whole_box && seen && std::abs(dc) > sub_reach;
          for (int k = sk; k < sk + kSub; ++k)
            for (int j = sj; j < sj + kSub; ++j)
              for (int a = si; a < si + kSub; ++a) {
                const int v = a + kBlockSide * (j + kBlockSide * k);
                if (settled) {
                  set(v, true, dc);
                  continue;
                }
                const Eigen::Vector3f p = voxel_pos(a, j, k);
                if (!in_box(p)) {
                  set(v, true, trunc);  // outside the carved region: free space
                  continue;
                }
                float d;
                const bool observed = field(p, trunc, &d);
                set(v, observed, d);
              }
        }
    blocks.set_flags(index[i], BlockFlagsOf(has_neg, has_pos, has_band));
  });
  stats_.blocks_filled = im.near.size();
  stats_.fill_ms = sw.ElapsedMs();
  return OkStatus();
}

}  // namespace holo
