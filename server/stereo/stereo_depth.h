// Depth from active-stereo pods: disparity → depth in the pod's depth camera,
// and a FrameSource that turns the synthetic studio's IR pairs into depth
// with PatchMatch, so every stage downstream runs unchanged on stereo depth.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "common/frame_source.h"
#include "common/image.h"
#include "common/rig.h"
#include "common/status.h"
#include "server/stereo/patchmatch.h"
#include "server/stereo/stereo_roi.h"
#include "studio/stereo_render.h"
#include "studio/studio.h"

namespace holo {

// Depth (mm, 0 = invalid) in `pod`'s depth camera from a left-IR disparity
// map (pixels, 0 = invalid): z = fx·baseline / d. When the IR intrinsics
// equal the depth camera's, pixel for pixel; otherwise each IR pixel is
// re-projected into the depth camera (nearest surface wins). Depth beyond
// `max_range_m` is dropped. InvalidArgument if `pod` is not a stereo pod or
// the disparity size differs from its IR intrinsics.
Status DisparityToDepth(const PodCalibration& pod, const ImageFloat& disparity, float max_range_m,
                        ImageDepth16* depth);

// PatchMatch's disparity search range for a pod whose surfaces lie between
// `near_m` and `far_m`: [fx·B/far, fx·B/near].
void StereoSearchRange(const PodCalibration& pod, float near_m, float far_m, PatchMatchOptions* options);

// SegmenterOptions::depth_edge_band_px for a site on stereo depth: within 3
// pixels of a depth edge colour decides, since the matcher's windows spread
// the nearer surface's depth past its edge (docs/stereo.md, "Stereo depth at
// the site": the site's mask IoU 0.74 -> 0.86 on S8-QVGA).
constexpr int kStereoSegmentEdgeBandPx = 3;

struct StereoDepthOptions {
  StereoRenderOptions render;
  PatchMatchOptions patchmatch;  // its disparity range is set per rig from near_m / far_m
  float near_m = 0.5f, far_m = 6.0f;
  // Match only around the person (stereo_roi.h); roi.fps is set from the
  // studio's. roi.enabled = false: every pair whole.
  StereoRoiOptions roi;
  Status Check() const;
};

// The synthetic studio with stereo depth: Next() renders the studio's frame
// (colour, as before), every pod's IR pair, runs PatchMatch on each pair and
// replaces the pod's depth with the stereo depth. Pods of the studio's rig
// without a stereo block get the default one (WithStereoPods). With
// options.roi enabled each pod's pair is matched in the region its
// StereoRoiPolicy gives (frames in order: the previous frame's foreground).
class StereoStudioSource final : public FrameSource {
 public:
  // `studio` is borrowed for the source's lifetime.
  static StatusOr<std::unique_ptr<StereoStudioSource>> Create(SyntheticStudio* studio, StereoDepthOptions options);

  // The studio's rig with the stereo blocks used.
  const Rig& rig() const override { return renderer_->rig(); }
  Status Next(RgbdFrameSet* out) override;
  int64_t num_frames() const override { return -1; }
  Status Seek(int64_t index) override;
  // Passes over `n` frames without rendering or matching them (a paced site
  // that fell behind takes the camera's current frame: reading the skipped
  // ones, at ~0.4 s each, left it ever further behind and it sent nothing).
  // The region policy sees the gap and matches the next pairs whole.
  Status Skip(int64_t n) override;

  // Renders frame `frame_index` with stereo depth; `pairs` (optional) gets the IR pairs and their truth.
  Status RenderFrame(int64_t frame_index, RgbdFrameSet* out, std::vector<StereoPair>* pairs);
  // Wall time of the stereo matching of the last frame (all pods), ms.
  double last_match_ms() const { return last_match_ms_; }
  // Pods whose whole pair was matched, or searched with SGBM
  // (StereoRoiOptions::search_with_sgbm), in the last frame; and the share
  // of the left images PatchMatch matched (1 = all of every pod's).
  int last_full_pods() const { return last_full_pods_; }
  double last_matched_fraction() const { return last_matched_fraction_; }

 private:
  StereoStudioSource() = default;
  SyntheticStudio* studio_ = nullptr;
  StereoDepthOptions options_;
  std::unique_ptr<StereoStudioRenderer> renderer_;
  std::vector<std::unique_ptr<PatchMatchStereo>> matchers_;  // one, or one per pod (temporal)
  std::vector<StereoRoiPolicy> roi_;  // per pod
  std::vector<StereoPair> pairs_;
  ImageFloat disparity_;
  int64_t next_frame_ = 0;
  double last_match_ms_ = 0;
  int last_full_pods_ = 0;
  double last_matched_fraction_ = 1;
};

}  // namespace holo
