#include "studio/studio.h"

#include "common/worker_pool.h"

#include <atomic>
#include <cmath>
#include <condition_variable>
#include <functional>
#include <mutex>
#include <thread>

#include "studio/render.h"
#include "studio/scene.h"

namespace holo {
Status DepthNoiseOptions::Check() const {
  if (!(sigma_at_1m_mm >= 0.0f && sigma_at_1m_mm <= 100.0f))
    return InvalidArgument("noise.sigma_at_1m_mm must be in [0, 100], got " + FormatNumber(sigma_at_1m_mm));
  if (!(grazing_dropout_deg > 0.0f && grazing_dropout_deg <= 90.0f))
    return InvalidArgument("noise.grazing_dropout_deg must be in (0, 90], got " + FormatNumber(grazing_dropout_deg));
  if (!(flying_edge_mm > 0.0f && std::isfinite(flying_edge_mm)))
    return InvalidArgument("noise.flying_edge_mm must be > 0, got " + FormatNumber(flying_edge_mm));
  if (!(flying_pixel_prob >= 0.0f && flying_pixel_prob <= 1.0f))
    return InvalidArgument("noise.flying_pixel_prob must be in [0, 1], got " + FormatNumber(flying_pixel_prob));
  if (!(random_dropout_prob >= 0.0f && random_dropout_prob <= 1.0f))
    return InvalidArgument("noise.random_dropout_prob must be in [0, 1], got " + FormatNumber(random_dropout_prob));
  if (!(max_range_m > 0.0f && max_range_m <= 65.0f))
    return InvalidArgument("noise.max_range_m must be in (0, 65], got " + FormatNumber(max_range_m));
  return OkStatus();
}

Status StudioOptions::Check() const {
  if (num_figures < 1 || num_figures > 2)
    return InvalidArgument("num_figures must be 1 or 2, got " + FormatNumber(num_figures));
  if (num_props < 0 || num_props > 2)
    return InvalidArgument("num_props must be in [0, 2], got " + FormatNumber(num_props));
  if (!(fps > 0.0 && fps <= 1000.0)) return InvalidArgument("fps must be in (0, 1000], got " + FormatNumber(fps));
  if (threads < 0 || threads > 256)
    return InvalidArgument("threads must be in [0, 256], got " + FormatNumber(threads));
  return noise.Check();
}

struct SyntheticStudio::Impl {
  struct PodViews {
    studio::ViewCache depth;
    studio::ViewCache color;  // used only when the pod is not registered
    bool registered = true;
    studio::ColorVariation variation;
  };

  Impl(const Rig& rig, const StudioOptions& options)
      : scene(studio::SceneConfig{options.num_figures, options.num_props, options.empty_room}),
        pool(options.threads) {  // 0: one thread per core
    pods.resize(rig.pods.size());
    pool.Run(static_cast<int>(rig.pods.size()), [&](int i, int) {
      const PodCalibration& pod = rig.pods[i];
      PodViews& v = pods[i];
      v.registered = pod.IsRegistered();
      v.depth.Init(pod.DepthCamera());
      if (!v.registered) v.color.Init(pod.ColorCamera());
      v.variation = studio::PodColorVariation(options.seed, pod.id);
    });
    scratch.resize(static_cast<size_t>(pool.num_threads()));
  }

  // Poses the scene and builds the shadow map, split into row bands over `pool` if given.
  void PoseFrame(int64_t frame_index, double fps, studio::FrameScene* fs, WorkerPool* workers) const {
    if (fs->frame == frame_index && frame_index >= 0) return;
    scene.Pose(static_cast<double>(frame_index) / fps, &fs->positions, &fs->normals, &fs->part_poses);
    fs->shadow.Prepare(fs->positions);
    const int bands = workers ? workers->num_threads() : 1;
    const int rows = fs->shadow.h;
    auto band = [&](int b, int) {
      fs->shadow.Rasterize(fs->positions, scene.tmpl().triangles, rows * b / bands, rows * (b + 1) / bands);
    };
    if (workers) workers->Run(bands, band);
    else band(0, 0);
    fs->frame = frame_index;
  }

  studio::Scene scene;
  WorkerPool pool;
  std::vector<PodViews> pods;
  std::vector<studio::RenderScratch> scratch;  // one per worker
  studio::FrameScene frame;
};

SyntheticStudio::SyntheticStudio(Rig rig, StudioOptions options) : rig_(std::move(rig)), options_(options) {
  const Status rs = rig_.Check();
  HOLO_CHECK_MSG(rs.ok(), rs.ToString());
  const Status os = options_.Check();
  HOLO_CHECK_MSG(os.ok(), os.ToString());
  impl_ = std::make_unique<Impl>(rig_, options_);
}

SyntheticStudio::~SyntheticStudio() = default;

StatusOr<std::unique_ptr<SyntheticStudio>> SyntheticStudio::Create(Rig rig, StudioOptions options) {
  HOLO_RETURN_IF_ERROR(rig.Check().WithContext("rig " + rig.name));
  if (rig.pods.empty()) return InvalidArgument("rig " + rig.name + " has no pods");
  HOLO_RETURN_IF_ERROR(options.Check().WithContext("studio options"));
  return std::make_unique<SyntheticStudio>(std::move(rig), options);
}

int64_t SyntheticStudio::TimestampUs(int64_t frame_index) const {
  return static_cast<int64_t>(std::llround(static_cast<double>(frame_index) * 1e6 / options_.fps));
}

std::vector<StudioSoundEvent> SyntheticStudio::SoundEvents(double t0_s, double t1_s) const {
  std::vector<std::pair<double, int>> raw;
  impl_->scene.SoundEvents(t0_s, t1_s, &raw);
  std::vector<StudioSoundEvent> out;
  out.reserve(raw.size());
  for (const auto& [t, kind] : raw) out.push_back({t, kind == 0 ? StudioSoundEvent::kFootfall : StudioSoundEvent::kBounce});
  return out;
}

Pose SyntheticStudio::HeadPose(double t_s, int figure) const { return impl_->scene.HeadPose(t_s, figure); }

void SyntheticStudio::RenderFrame(int64_t frame_index, RgbdFrameSet* frames, StudioGroundTruth* gt) {
  Impl& im = *impl_;
  im.PoseFrame(frame_index, options_.fps, &im.frame, &im.pool);
  const int num_pods = static_cast<int>(rig_.pods.size());
  const int64_t ts = TimestampUs(frame_index);
  frames->frame_index = frame_index;
  frames->frames.resize(num_pods);
  if (gt) {
    gt->frame_index = frame_index;
    gt->timestamp_us = ts;
    gt->depth.resize(num_pods);
    gt->mask.resize(num_pods);
  }
  const studio::SceneTemplate& tmpl = im.scene.tmpl();
  im.pool.Run(num_pods, [&](int i, int worker) {
    RenderPodInto(i, worker, frame_index, &frames->frames[i], gt ? &gt->depth[i] : nullptr,
                  gt ? &gt->mask[i] : nullptr);
  });
  if (gt) {
    Mesh& m = gt->foreground_mesh;
    m.positions.assign(im.frame.positions.begin(), im.frame.positions.end());
    m.normals.assign(im.frame.normals.begin(), im.frame.normals.end());
    m.colors.assign(tmpl.vertex_albedo.begin(), tmpl.vertex_albedo.end());
    m.triangles.assign(tmpl.triangles.begin(), tmpl.triangles.end());
  }
}

void SyntheticStudio::RenderPodInto(int i, int worker, int64_t frame_index, RgbdFrame* out, ImageDepth16* gt_depth,
                                    ImageGray8* gt_mask) {
  Impl& im = *impl_;
  Impl::PodViews& v = im.pods[i];
  studio::RenderScratch& s = im.scratch[worker];
  const studio::SceneTemplate& tmpl = im.scene.tmpl();
  RgbdFrame& f = *out;
  f.pod_id = rig_.pods[i].id;
  f.timestamp_us = TimestampUs(frame_index);
  f.mask = ImageGray8();
  studio::RenderViewCore(v.depth, tmpl, im.frame, v.registered, &s);
  if (options_.depth_noise) {
    const uint64_t stream = studio::HashOf(options_.seed, static_cast<uint64_t>(frame_index),
                                           static_cast<uint64_t>(rig_.pods[i].id), 0xDE9ULL);
    studio::WriteNoisyDepth(v.depth, s, options_.noise, stream, &f.depth);
  } else {
    studio::WriteTruth(v.depth, s, &f.depth, nullptr);
  }
  if (gt_depth) studio::WriteTruth(v.depth, s, gt_depth, gt_mask);
  if (!v.registered) studio::RenderViewCore(v.color, tmpl, im.frame, true, &s);
  studio::WriteColor(v.registered ? v.depth : v.color, s, options_.color_variation ? &v.variation : nullptr, &f.color);
}

void SyntheticStudio::RenderPod(int64_t frame_index, int pod_index, RgbdFrame* out) {
  HOLO_CHECK(pod_index >= 0 && pod_index < static_cast<int>(rig_.pods.size()));
  Impl& im = *impl_;
  im.PoseFrame(frame_index, options_.fps, &im.frame, &im.pool);
  RenderPodInto(pod_index, 0, frame_index, out, nullptr, nullptr);
}

Mesh SyntheticStudio::ForegroundMesh(int64_t frame_index) const {
  const studio::SceneTemplate& tmpl = impl_->scene.tmpl();
  Mesh m;
  std::vector<Eigen::Isometry3f> poses;
  impl_->scene.Pose(static_cast<double>(frame_index) / options_.fps, &m.positions, &m.normals, &poses);
  m.colors = tmpl.vertex_albedo;
  m.triangles = tmpl.triangles;
  return m;
}

void SyntheticStudio::RenderView(int64_t frame_index, const CameraModel& camera, ImageRgb8* color, ImageDepth16* depth,
                                 ImageGray8* mask) const {
  studio::FrameScene fs;
  impl_->PoseFrame(frame_index, options_.fps, &fs, nullptr);
  studio::ViewCache view;
  view.Init(camera);
  studio::RenderScratch s;
  studio::RenderViewCore(view, impl_->scene.tmpl(), fs, color != nullptr, &s);
  if (color) studio::WriteColor(view, s, nullptr, color);
  studio::WriteTruth(view, s, depth, mask);
}

void SyntheticStudio::WithPosedFrame(int64_t frame_index, const PosedFrameFn& fn) {
  Impl& im = *impl_;
  im.PoseFrame(frame_index, options_.fps, &im.frame, &im.pool);
  fn(im.scene.tmpl(), im.frame, &im.pool);
}

Status SyntheticStudio::Next(RgbdFrameSet* out) {
  RenderFrame(next_frame_, out, nullptr);
  ++next_frame_;
  return OkStatus();
}

Status SyntheticStudio::Skip(int64_t n) {
  if (n < 0) return InvalidArgument("skip of " + std::to_string(n) + " frames");
  next_frame_ += n;
  return OkStatus();
}

Status SyntheticStudio::Seek(int64_t index) {
  if (index < 0) return OutOfRange("seek to frame " + std::to_string(index) + " before the start");
  next_frame_ = index;
  return OkStatus();
}

}  // namespace holo
