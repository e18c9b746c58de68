#include "server/stereo/stereo_depth.h"

#include <algorithm>
#include <chrono>
#include <cmath>

namespace holo {

Status DisparityToDepth(const PodCalibration& pod, const ImageFloat& disparity, float max_range_m,
                        ImageDepth16* depth) {
  if (!pod.stereo.enabled) return InvalidArgument("pod " + std::to_string(pod.id) + " is not a stereo pod");
  const Intrinsics& ir = pod.stereo.ir;
  if (disparity.width() != ir.width || disparity.height() != ir.height)
    return InvalidArgument("disparity is " + std::to_string(disparity.width()) + "x" +
                           std::to_string(disparity.height()) + ", pod " + std::to_string(pod.id) + "'s IR camera is " +
                           std::to_string(ir.width) + "x" + std::to_string(ir.height));
  const Intrinsics& dk = pod.depth;
  if (depth->width() != dk.width || depth->height() != dk.height) depth->Resize(dk.width, dk.height);
  depth->Fill(0);
  const float fb_mm = static_cast<float>(ir.fx * pod.stereo.baseline_m * 1000.0);
  const float max_mm = std::min(max_range_m * 1000.0f, 65535.0f);
  const bool same = ir.width == dk.width && ir.height == dk.height && ir.fx == dk.fx && ir.fy == dk.fy &&
                    ir.cx == dk.cx && ir.cy == dk.cy && !dk.HasDistortion();
  const CameraModel ir_cam{ir, Pose::Identity()}, depth_cam{dk, Pose::Identity()};
  for (int y = 0; y < ir.height; ++y) {
    const float* d = disparity.row(y);
    for (int x = 0; x < ir.width; ++x) {
      if (!(d[x] > 0.0f)) continue;
      const float z_mm = fb_mm / d[x];
      if (!(z_mm <= max_mm)) continue;
      const uint16_t v = static_cast<uint16_t>(std::lround(z_mm));
      if (same) {
        depth->at(x, y) = v;
        continue;
      }
      Eigen::Vector2f px;
      if (!depth_cam.ProjectCamera(ir_cam.UnprojectCamera(Eigen::Vector2f(x, y), z_mm * 1e-3f), &px)) continue;
      const int ix = static_cast<int>(std::lround(px.x())), iy = static_cast<int>(std::lround(px.y()));
      if (!depth->Contains(ix, iy)) continue;
      uint16_t& o = depth->at(ix, iy);
      if (o == 0 || v < o) o = v;
    }
  }
  return OkStatus();
}

void StereoSearchRange(const PodCalibration& pod, float near_m, float far_m, PatchMatchOptions* options) {
  const float fb = static_cast<float>(pod.stereo.ir.fx * pod.stereo.baseline_m);
  options->min_disparity = std::max(0.0f, std::floor(fb / far_m));
  options->max_disparity = std::ceil(fb / near_m);
}

Status StereoDepthOptions::Check() const {
  HOLO_RETURN_IF_ERROR(render.Check().WithContext("render"));
  HOLO_RETURN_IF_ERROR(roi.Check().WithContext("roi"));
  if (!(near_m > 0.05f && far_m > near_m && far_m <= 65.0f))
    return InvalidArgument("need 0.05 < near_m < far_m <= 65, got near_m " + FormatNumber(near_m) + ", far_m " +
                           FormatNumber(far_m));
  return OkStatus();
}

StatusOr<std::unique_ptr<StereoStudioSource>> StereoStudioSource::Create(SyntheticStudio* studio,
                                                                         StereoDepthOptions options) {
  if (studio == nullptr) return InvalidArgument("stereo source: no studio");
  HOLO_RETURN_IF_ERROR(options.Check().WithContext("stereo depth options"));
  HOLO_ASSIGN_OR_RETURN(auto renderer,
                        StereoStudioRenderer::Create(studio, WithStereoPods(studio->rig()), options.render));
  // One search range for all pods: the widest.
  PatchMatchOptions pm = options.patchmatch;
  float lo = 1e9f, hi = 0.0f;
  for (const auto& pod : renderer->rig().pods) {
    PatchMatchOptions r = pm;
    StereoSearchRange(pod, options.near_m, options.far_m, &r);
    lo = std::min(lo, r.min_disparity);
    hi = std::max(hi, r.max_disparity);
  }
  pm.min_disparity = lo;
  pm.max_disparity = hi;
  std::unique_ptr<StereoStudioSource> s(new StereoStudioSource());
  // One matcher for all pods, or one per pod when each starts from its own
  // last planes (PatchMatchOptions::temporal).
  const size_t matchers = pm.temporal ? renderer->rig().pods.size() : 1;
  for (size_t i = 0; i < matchers; ++i) {
    HOLO_ASSIGN_OR_RETURN(auto matcher, PatchMatchStereo::Create(pm));
    s->matchers_.push_back(std::move(matcher));
  }
  s->studio_ = studio;
  s->options_ = options;
  s->options_.patchmatch = pm;
  s->renderer_ = std::move(renderer);
  StereoRoiOptions roi = options.roi;
  roi.fps = studio->options().fps;
  HOLO_RETURN_IF_ERROR(roi.Check().WithContext("stereo region options"));
  const auto& pods = s->renderer_->rig().pods;
  for (size_t i = 0; i < pods.size(); ++i) {
    roi.full_phase = StereoRoiPolicy::FullPhase(i, pods.size(), roi.full_every);  // pods take turns
    s->roi_.emplace_back(pods[i], roi);
  }
  return s;
}

Status StereoStudioSource::RenderFrame(int64_t frame_index, RgbdFrameSet* out, std::vector<StereoPair>* pairs) {
  studio_->RenderFrame(frame_index, out, nullptr);
  std::vector<StereoPair>& p = pairs ? *pairs : pairs_;
  renderer_->Render(frame_index, &p);
  const auto t0 = std::chrono::steady_clock::now();
  const Rig& rig = renderer_->rig();
  last_full_pods_ = 0;
  int64_t matched = 0, total = 0;
  for (size_t i = 0; i < rig.pods.size(); ++i) {
    PatchMatchStereo* matcher = matchers_[std::min(i, matchers_.size() - 1)].get();
    HOLO_ASSIGN_OR_RETURN(const RowSpans region,
                          roi_[i].Match(matcher, frame_index, p[i].left, p[i].right, &disparity_));
    last_full_pods_ += region.IsFull(p[i].left.width()) || roi_[i].searched();
    matched += region.area();
    total += static_cast<int64_t>(p[i].left.width()) * p[i].left.height();
    HOLO_RETURN_IF_ERROR(DisparityToDepth(rig.pods[i], disparity_, options_.far_m, &out->frames[i].depth));
  }
  last_matched_fraction_ = total > 0 ? static_cast<double>(matched) / static_cast<double>(total) : 1.0;
  last_match_ms_ = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  return OkStatus();
}

Status StereoStudioSource::Next(RgbdFrameSet* out) {
  HOLO_RETURN_IF_ERROR(RenderFrame(next_frame_, out, nullptr));
  ++next_frame_;
  return OkStatus();
}

Status StereoStudioSource::Skip(int64_t n) {
  if (n < 0) return InvalidArgument("skip of " + std::to_string(n) + " frames");
  next_frame_ += n;
  return OkStatus();
}

Status StereoStudioSource::Seek(int64_t index) {
  if (index < 0) return OutOfRange("seek to frame " + std::to_string(index) + " before the start");
  next_frame_ = index;
  return OkStatus();
}

}  // namespace holo
