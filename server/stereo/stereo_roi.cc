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
  if (!(max_gap_s > 0.0 && std::isfinite(max_gap_s)))
    return InvalidArgument("max_gap_s must be > 0, got " + FormatNumber(max_gap_s));
  if (sample_step < 1 || sample_step > 16)
    return InvalidArgument("sample_step must be in [1, 16], got " + FormatNumber(sample_step));
  if (min_line_samples < 1) return InvalidArgument("min_line_samples must be >= 1, got " + FormatNumber(min_line_samples));
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
  if (!options_.enabled || !have_previous_ || full_due_ || box_.empty()) return full;
  if (frame_index <= previous_frame_) return full;  // a step back (seek): the previous frame says nothing
  const double dt = static_cast<double>(frame_index - previous_frame_) / options_.fps;
  if (dt > options_.max_gap_s) return full;
  if (frame_index - last_full_frame_ >= options_.full_every) return full;
  // The motion since the previous frame, in pixels at the nearest foreground.
  const double move_m = options_.max_speed_mps * dt;
  const double z = std::max(0.05, static_cast<double>(nearest_fg_m_));
  const int mx = options_.margin_px + static_cast<int>(std::ceil(pod_.stereo.ir.fx * move_m / z));
  const int my = options_.margin_px + static_cast<int>(std::ceil(pod_.stereo.ir.fy * move_m / z));
  return ImageRect{box_.x0 - mx, box_.y0 - my, box_.x1 + mx, box_.y1 + my}.Clipped(width_, height_);
}

void StereoRoiPolicy::Update(int64_t frame_index, const ImageRect& region, const ImageFloat& disparity) {
  const ImageRect reg = region.Clipped(width_, height_);
  have_previous_ = true;
  previous_frame_ = frame_index;
  if (reg == ImageRect::Full(width_, height_)) last_full_frame_ = frame_index;
  box_ = ImageRect{};
  full_due_ = true;
  nearest_fg_m_ = 0;
  if (reg.empty() || disparity.width() != width_ || disparity.height() != height_) return;

  // Foreground samples: pixels whose point lies in the capture volume. On a
  // grid aligned to the image (not the region), so a region does not move
  // the samples.
  const int step = options_.sample_step;
  const CameraModel cam = pod_.LeftIrCamera();
  const float fb = static_cast<float>(pod_.stereo.ir.fx * pod_.stereo.baseline_m);
  const float r2 = options_.volume_radius_m * options_.volume_radius_m;
  std::vector<int> col(static_cast<size_t>(width_), 0), row(static_cast<size_t>(height_), 0);
  float nearest = 1e30f;
  const int sy0 = (reg.y0 + step - 1) / step * step, sx0 = (reg.x0 + step - 1) / step * step;
  for (int y = sy0; y < reg.y1; y += step) {
    const float* d = disparity.row(y);
    for (int x = sx0; x < reg.x1; x += step) {
      if (!(d[x] > 0.0f)) continue;
      const float z = fb / d[x];
      const Eigen::Vector3f p = cam.UnprojectWorld(Eigen::Vector2f(static_cast<float>(x), static_cast<float>(y)), z);
      if (p.z() < options_.volume_min_z_m || p.z() > options_.volume_max_z_m) continue;
      if (p.x() * p.x() + p.y() * p.y() > r2) continue;
      ++col[static_cast<size_t>(x)];
      ++row[static_cast<size_t>(y)];
      nearest = std::min(nearest, z);
    }
  }
  const int need = options_.min_line_samples;
  ImageRect box{width_, height_, -1, -1};
  for (int x = 0; x < width_; ++x)
    if (col[static_cast<size_t>(x)] >= need) {
      box.x0 = std::min(box.x0, x);
      box.x1 = std::max(box.x1, std::min(width_, x + step));
    }
  for (int y = 0; y < height_; ++y)
    if (row[static_cast<size_t>(y)] >= need) {
      box.y0 = std::min(box.y0, y);
      box.y1 = std::max(box.y1, std::min(height_, y + step));
    }
  if (box.empty()) return;  // nobody: the whole image next time
  box_ = box;
  nearest_fg_m_ = nearest;
  // Touching an edge of the region that is not the image's: the person may
  // reach beyond what was matched.
  const int t = options_.touch_px;
  const bool touch = (reg.x0 > 0 && box.x0 - reg.x0 <= t) || (reg.y0 > 0 && box.y0 - reg.y0 <= t) ||
                     (reg.x1 < width_ && reg.x1 - box.x1 <= t) || (reg.y1 < height_ && reg.y1 - box.y1 <= t);
  full_due_ = touch;
}

}  // namespace holo
