#include "server/stereo/stereo_roi.h"

#include <algorithm>
#include <cmath>
#include <vector>

namespace holo {

Status StereoRoiOptions::Check() const {
  if (!(volume_radius_m > 0.0f && std::isfinite(volume_radius_m)))
    return InvalidArgument("volume_radius_m must be > 0, got " + FormatNumber(volume_radius_m));
  if (!(std::isfinite(volume_min_z_m) && std::isfinite(volume_max_z_m) && volume_max_z_m > volume_min_z_m))
    return InvalidArgument("need volume_min_z_m < volume_max_z_m, got " + FormatNumber(volume_min_z_m) + " and " +
                           FormatNumber(volume_max_z_m));
  if (!(max_speed_mps >= 0.0f && max_speed_mps <= 100.0f))
    return InvalidArgument("max_speed_mps must be in [0, 100], got " + FormatNumber(max_speed_mps));
  if (margin_px < 0 || margin_px > 1000) return InvalidArgument("margin_px must be in [0, 1000], got " + FormatNumber(margin_px));
  if (!(fps > 0.0 && fps <= 1000.0)) return InvalidArgument("fps must be in (0, 1000], got " + FormatNumber(fps));
  if (full_every < 1) return InvalidArgument("full_every must be >= 1, got " + FormatNumber(full_every));
  if (full_phase < 0) return InvalidArgument("full_phase must be >= 0, got " + FormatNumber(full_phase));
  if (!(max_gap_s > 0.0 && std::isfinite(max_gap_s)))
    return InvalidArgument("max_gap_s must be > 0, got " + FormatNumber(max_gap_s));
  if (sample_step < 1 || sample_step > 16)
    return InvalidArgument("sample_step must be in [1, 16], got " + FormatNumber(sample_step));
  if (min_neighbours < 0 || min_neighbours > 8)
    return InvalidArgument("min_neighbours must be in [0, 8], got " + FormatNumber(min_neighbours));
  if (min_vertical_run < 1 || min_vertical_run > 1000)
    return InvalidArgument("min_vertical_run must be in [1, 1000], got " + FormatNumber(min_vertical_run));
  if (min_group_samples < 1) return InvalidArgument("min_group_samples must be >= 1, got " + FormatNumber(min_group_samples));
  if (min_line_samples < 1) return InvalidArgument("min_line_samples must be >= 1, got " + FormatNumber(min_line_samples));
  if (touch_min_run < 1) return InvalidArgument("touch_min_run must be >= 1, got " + FormatNumber(touch_min_run));
  if (std::isnan(disparity_margin_px)) return InvalidArgument("disparity_margin_px is NaN");
  if (touch_px < 0) return InvalidArgument("touch_px must be >= 0, got " + FormatNumber(touch_px));
  return OkStatus();
}

StereoRoiPolicy::StereoRoiPolicy(const PodCalibration& pod, StereoRoiOptions options)
    : pod_(pod), options_(options), width_(pod.stereo.ir.width), height_(pod.stereo.ir.height) {
  const Status s = options_.Check();
  HOLO_CHECK_MSG(s.ok(), s.ToString());
  HOLO_CHECK_MSG(pod_.stereo.enabled, "stereo region policy for pod " + std::to_string(pod_.id) + ": not a stereo pod");
}

ImageRect StereoRoiPolicy::Next(int64_t frame_index) {
  const ImageRect full = ImageRect::Full(width_, height_);
  max_disparity_ = 3.0e38f;
  const auto whole = [&] {
    spans_ = RowSpans::FromRect(full, width_, height_);
    return full;
  };
  if (!options_.enabled || !have_previous_ || full_due_ || box_.empty()) return whole();
  if (frame_index <= previous_frame_) return whole();  // a step back (seek): the previous frame says nothing
  const double dt = static_cast<double>(frame_index - previous_frame_) / options_.fps;
  if (dt > options_.max_gap_s) return whole();
  if (frame_index - last_full_frame_ >= options_.full_every) return whole();
  if ((frame_index + options_.full_phase) % options_.full_every == 0) return whole();
  return RegionAround(dt);
}

ImageRect StereoRoiPolicy::RegionAround(double dt) {
  max_disparity_ = 3.0e38f;
  // The motion since the previous frame, in pixels at the nearest foreground.
  const double move_m = options_.max_speed_mps * dt;
  const double z = std::max(0.05, static_cast<double>(nearest_fg_m_));
  const int mx = options_.margin_px + static_cast<int>(std::ceil(pod_.stereo.ir.fx * move_m / z));
  const int my = options_.margin_px + static_cast<int>(std::ceil(pod_.stereo.ir.fy * move_m / z));
  if (options_.disparity_margin_px >= 0.0f)
    max_disparity_ = static_cast<float>(pod_.stereo.ir.fx * pod_.stereo.baseline_m / std::max(0.05, z - move_m)) +
                     options_.disparity_margin_px;
  const ImageRect box = ImageRect{box_.x0 - mx, box_.y0 - my, box_.x1 + mx, box_.y1 + my}.Clipped(width_, height_);
  spans_ = RowSpans::FromRect(box, width_, height_);
  if (!options_.row_spans) return box;
  // Row y: the extent of the foreground's samples on the rows within `my`
  // of it, widened by `mx`, inside the box.
  const int step = options_.sample_step;
  const int gh = static_cast<int>(ext0_.size());
  for (int y = box.y0; y < box.y1; ++y) {
    const int lo = y - my - step + 1;  // sample row gy covers pixel rows [gy·step, gy·step + step)
    const int g0 = lo <= 0 ? 0 : (lo + step - 1) / step, g1 = std::min(gh - 1, (y + my) / step);
    int a = width_, e = 0;
    for (int gy = g0; gy <= g1; ++gy) {
      if (ext1_[static_cast<size_t>(gy)] <= ext0_[static_cast<size_t>(gy)]) continue;
      a = std::min(a, ext0_[static_cast<size_t>(gy)]);
      e = std::max(e, ext1_[static_cast<size_t>(gy)]);
    }
    a = std::max(box.x0, a - mx);
    e = std::min(box.x1, e + mx);
    spans_.x0[static_cast<size_t>(y)] = e > a ? a : 0;
    spans_.x1[static_cast<size_t>(y)] = e > a ? e : 0;
  }
  return spans_.Bounds();
}

void StereoRoiPolicy::Update(int64_t frame_index, const RowSpans& region, const ImageFloat& disparity) {
  const ImageRect reg = region.Bounds().Clipped(width_, height_);
  have_previous_ = true;
  previous_frame_ = frame_index;
  if (region.rows() == height_ && region.IsFull(width_)) last_full_frame_ = frame_index;
  box_ = ImageRect{};
  full_due_ = true;
  nearest_fg_m_ = 0;
  ext0_.clear();
  ext1_.clear();
  if (reg.empty() || region.rows() != height_ || disparity.width() != width_ || disparity.height() != height_) return;

  // Foreground samples: pixels whose point lies in the capture volume. On a
  // grid aligned to the image (not the region), so a region does not move
  // the samples.
  const int step = options_.sample_step;
  const int gw = (width_ + step - 1) / step, gh = (height_ + step - 1) / step;
  const CameraModel cam = pod_.LeftIrCamera();
  const float fb = static_cast<float>(pod_.stereo.ir.fx * pod_.stereo.baseline_m);
  const float r2 = options_.volume_radius_m * options_.volume_radius_m;
  fg_.assign(static_cast<size_t>(gw) * gh, 0);
  zs_.assign(fg_.size(), 0.0f);
  for (int gy = (reg.y0 + step - 1) / step; gy * step < reg.y1; ++gy) {
    const float* d = disparity.row(gy * step);
    for (int gx = (reg.x0 + step - 1) / step; gx * step < reg.x1; ++gx) {
      const int x = gx * step;
      if (!(d[x] > 0.0f)) continue;
      const float z = fb / d[x];
      const Eigen::Vector3f p = cam.UnprojectWorld(Eigen::Vector2f(static_cast<float>(x), static_cast<float>(gy * step)), z);
      if (p.z() < options_.volume_min_z_m || p.z() > options_.volume_max_z_m) continue;
      if (p.x() * p.x() + p.y() * p.y() > r2) continue;
      fg_[static_cast<size_t>(gy) * gw + gx] = 1;
      zs_[static_cast<size_t>(gy) * gw + gx] = z;
    }
  }
  // A sample counts only inside a vertical run of at least
  // `min_vertical_run` foreground samples, and with at least
  // `min_neighbours` of its 8 grid neighbours in the volume too: mismatches
  // come as thin streaks along rows (on the far floor, 1–3 px tall, stacked
  // with gaps; measured, they stretched the box over 80–97 % of some pods'
  // images), while a person's limbs, the ball, a head are several samples
  // tall. Then the box spans the columns and rows with at least
  // `min_line_samples` such samples.
  run_.assign(fg_.size(), 0);
  for (int gx = 0; gx < gw; ++gx)
    for (int gy = 0; gy < gh;) {
      if (!fg_[static_cast<size_t>(gy) * gw + gx]) {
        ++gy;
        continue;
      }
      int end = gy;
      while (end < gh && fg_[static_cast<size_t>(end) * gw + gx]) ++end;
      for (int k = gy; k < end; ++k) run_[static_cast<size_t>(k) * gw + gx] = static_cast<uint16_t>(std::min(end - gy, 65535));
      gy = end;
    }
  // Core samples: in a long enough vertical run, with enough neighbours.
  core_.assign(fg_.size(), 0);
  for (int gy = 1; gy + 1 < gh; ++gy)
    for (int gx = 1; gx + 1 < gw; ++gx) {
      const size_t i = static_cast<size_t>(gy) * gw + gx;
      if (!fg_[i] || run_[i] < options_.min_vertical_run) continue;
      int n = 0;
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) n += fg_[i + static_cast<size_t>(dy * gw + dx)];
      if (n - 1 >= options_.min_neighbours) core_[i] = 1;
    }
  // Connected groups of core samples (8-neighbours) smaller than
  // `min_group_samples` are dropped: stacks of streaks on the floor pass the
  // tests above in places, but as small groups apart from the person.
  std::vector<int> col(static_cast<size_t>(gw), 0), row(static_cast<size_t>(gh), 0);
  ext0_.assign(static_cast<size_t>(gh), width_);
  ext1_.assign(static_cast<size_t>(gh), 0);
  float nearest = 1e30f;
  std::vector<size_t>& stack = stack_;
  std::vector<size_t>& group = group_;
  for (size_t seed = 0; seed < core_.size(); ++seed) {
    if (core_[seed] != 1) continue;
    group.clear();
    stack.assign(1, seed);
    core_[seed] = 2;
    while (!stack.empty()) {
      const size_t i = stack.back();
      stack.pop_back();
      group.push_back(i);
      const int gx = static_cast<int>(i % static_cast<size_t>(gw)), gy = static_cast<int>(i / static_cast<size_t>(gw));
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const int nx = gx + dx, ny = gy + dy;
          if (nx < 0 || ny < 0 || nx >= gw || ny >= gh) continue;
          const size_t j = static_cast<size_t>(ny) * gw + nx;
          if (core_[j] != 1) continue;
          core_[j] = 2;
          stack.push_back(j);
        }
    }
    if (static_cast<int>(group.size()) < options_.min_group_samples) continue;
    for (const size_t i : group) {
      core_[i] = 3;  // kept
      const size_t gx = i % static_cast<size_t>(gw), gy = i / static_cast<size_t>(gw);
      ++col[gx];
      ++row[gy];
      nearest = std::min(nearest, zs_[i]);
      ext0_[gy] = std::min(ext0_[gy], static_cast<int>(gx) * step);
      ext1_[gy] = std::max(ext1_[gy], std::min(width_, (static_cast<int>(gx) + 1) * step));
    }
  }
  const int need = options_.min_line_samples;
  ImageRect box{width_, height_, -1, -1};
  for (int gx = 0; gx < gw; ++gx)
    if (col[static_cast<size_t>(gx)] >= need) {
      box.x0 = std::min(box.x0, gx * step);
      box.x1 = std::max(box.x1, std::min(width_, (gx + 1) * step));
    }
  for (int gy = 0; gy < gh; ++gy)
    if (row[static_cast<size_t>(gy)] >= need) {
      box.y0 = std::min(box.y0, gy * step);
      box.y1 = std::max(box.y1, std::min(height_, (gy + 1) * step));
    }
  if (box.empty()) return;  // nobody: the whole image next time
  box_ = box;
  nearest_fg_m_ = nearest;
  // Touching an edge of the region that is not the image's: the person may
  // reach beyond what was matched. A kept sample, or any foreground sample in
  // a vertical run of `touch_min_run` (not only kept ones: a person entering
  // across the edge shows first as a sliver too thin for the neighbour test;
  // stacked floor streaks make runs of 4–5 samples), with a pixel t + 1
  // left, right, above or below it (clamped to the image) outside the region.
  const int t = options_.touch_px;
  const auto touches = [&](int x, int y) {
    return !region.Contains(std::max(0, x - t - 1), y) || !region.Contains(std::min(width_ - 1, x + t + 1), y) ||
           !region.Contains(x, std::max(0, y - t - 1)) || !region.Contains(x, std::min(height_ - 1, y + t + 1));
  };
  bool touch = false;
  for (int gy = 0; gy < gh && !touch; ++gy)
    for (int gx = 0; gx < gw; ++gx) {
      const size_t i = static_cast<size_t>(gy) * gw + gx;
      if (core_[i] != 3 && (!fg_[i] || run_[i] < options_.touch_min_run)) continue;
      if (touches(gx * step, gy * step)) {
        touch = true;
        break;
      }
    }
  full_due_ = touch;
}

StatusOr<RowSpans> StereoRoiPolicy::Match(PatchMatchStereo* matcher, int64_t frame_index, const ImageGray8& left,
                                          const ImageGray8& right, ImageFloat* disparity) {
  Next(frame_index);
  searched_ = false;
  if (options_.enabled && options_.search_with_sgbm && spans_.IsFull(width_) && left.width() == width_ &&
      left.height() == height_ && right.width() == width_ && right.height() == height_) {
    // The whole pair is due: find the foreground with SGBM, then PatchMatch
    // around it only, from fresh planes (they refresh the temporal chain as
    // a whole pair did).
    searched_ = true;
    const PatchMatchOptions& mo = matcher->options();
    if (!sgbm_.matcher) sgbm_.matcher = std::make_unique<SgbmStereo>(mo.min_disparity, mo.max_disparity);
    sgbm_.matcher->Compute(left, right, &search_);
    Update(frame_index, spans_, search_);
    if (box_.empty()) {  // nobody there: no PatchMatch
      disparity->Resize(width_, height_, 0.0f);
      return RowSpans::FromRect(ImageRect{}, width_, height_);
    }
    RegionAround(2.0 / options_.fps);
    matcher->ForgetLast();
  }
  const RowSpans region = spans_;
  HOLO_RETURN_IF_ERROR(matcher->Compute(left, right, region, max_disparity(), disparity));
  Update(frame_index, region, *disparity);
  return region;
}

}  // namespace holo
