#include "texture/novel_view.h"

#include <algorithm>
#include <cmath>

#include "common/image_io.h"
#include "common/metrics/image_metrics.h"
#include "common/pose.h"
#include "texture/mesh_renderer.h"

namespace holo {

std::vector<NovelView> MakeNovelViews(const NovelViewOptions& options) {
  std::vector<NovelView> views;
  for (int i = 0; i < options.num_views; ++i) {
    const float az = options.first_azimuth_deg + 360.0f * static_cast<float>(i) / static_cast<float>(options.num_views);
    const float a = az * static_cast<float>(M_PI) / 180.0f;
    const Eigen::Vector3f eye(options.target.x() + options.radius_m * std::cos(a),
                              options.target.y() + options.radius_m * std::sin(a), options.height_m);
    NovelView v;
    v.camera.intrinsics = options.intrinsics;
    v.camera.world_from_camera = LookAt(eye, options.target);
    v.azimuth_deg = az;
    views.push_back(v);
  }
  return views;
}

StatusOr<NovelViewScore> ScoreNovelView(const SyntheticStudio& studio, int64_t frame, const Mesh& textured,
                                        const NovelView& view, const std::string& png_prefix) {
  ImageRgb8 truth, ours;
  ImageGray8 truth_mask;
  if (Status s = view.camera.intrinsics.Check(); !s.ok()) return s.WithContext("ScoreNovelView");
  studio.RenderView(frame, view.camera, &truth, nullptr, &truth_mask);
  if (Status s = RenderMesh(textured, view.camera, &ours, nullptr, nullptr); !s.ok()) return s;
  NovelViewScore score;
  score.azimuth_deg = view.azimuth_deg;
  for (size_t i = 0; i < truth_mask.num_pixels(); ++i) {
    if (truth_mask.data()[i]) {
      ++score.mask_pixels;
      continue;
    }
    for (int c = 0; c < 3; ++c) truth.data()[3 * i + c] = ours.data()[3 * i + c] = 0;
  }
  auto psnr = metrics::ComputePsnr(ours, truth, &truth_mask);
  if (!psnr.ok()) return psnr.status().WithContext("ScoreNovelView");
  auto ssim = metrics::ComputeSsim(ours, truth, &truth_mask);
  if (!ssim.ok()) return ssim.status().WithContext("ScoreNovelView");
  score.psnr_db = *psnr;
  score.ssim = *ssim;
  if (!png_prefix.empty()) {
    // Truth on the left, ours on the right.
    const int w = truth.width(), h = truth.height();
    ImageRgb8 both(2 * w, h);
    for (int y = 0; y < h; ++y) {
      std::copy(truth.row(y), truth.row(y) + 3 * w, both.row(y));
      std::copy(ours.row(y), ours.row(y) + 3 * w, both.row(y) + 3 * w);
    }
    if (Status s = WriteImageRgb8(png_prefix + ".png", both); !s.ok()) return s;
  }
  return score;
}

}  // namespace holo
