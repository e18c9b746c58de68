// Where a stereo pod matches: a rectangle around the person, from the
// previous frame's stereo depth, so PatchMatch (server/stereo/patchmatch.h)
// works on a fraction of the pair (docs/stereo.md, "Matching around the
// person").
//
// The site needs depth only where the person is, but segmentation
// (server/segment) needs depth, so the current frame's mask does not exist
// before stereo. The region therefore comes from the previous frame, and from
// the pod's own previous stereo depth rather than the site's mask of that
// pod, because:
//  * a network pod (holoport-pod --depth stereo) never sees the site's masks
//    (nothing flows from the site to a pod but refusals), and in the site
//    the masks are made stages downstream of the frame source, a pipeline
//    depth later; the pod's own depth is there in both, one frame old;
//  * the foreground test needs only the pod's calibration: a pixel is
//    foreground when its 3-D point (world frame, z up) lies in the capture
//    volume, a vertical cylinder around the world's z axis above the floor
//    (the floor, the walls and the ceiling are outside it). No background
//    model, no colour.
// The region is the foreground widened by a margin that covers the motion
// since that frame (max_speed_mps × elapsed time, in pixels at the nearest
// foreground depth) plus a fixed margin: row by row (each row the span of
// the foreground's samples on the rows within the margin, widened by it;
// RowSpans), or its bounding box (StereoRoiOptions::row_spans off). Spans
// hold the same motion as the box (every sample moved by up to the margin
// in x and y stays inside) on ~0.6 of the box's pixels for the studio's
// person, whose arms and legs leave most of the box empty. The whole
// image is matched instead on the first frame, every `full_every` frames,
// after a gap longer than `max_gap_s` or a step back in time, when the
// previous result had no foreground, and when its foreground touched an edge
// of its region that is not the image's edge (the person may go on beyond
// it). Pods take turns for the periodic full match (full_phase). So a person who enters the view is found on the next frame when the
// view was empty or when they enter touching the current region, and
// otherwise (a second person entering away from the first) at the next
// periodic full match: at most `full_every` − 1 frames late. A "full match"
// is by default a search (StereoRoiOptions::search_with_sgbm): OpenCV's SGBM
// over the whole pair finds the foreground, and PatchMatch runs only around
// it (docs/stereo.md, "Searching whole pairs with SGBM").
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "common/image.h"
#include "common/rig.h"
#include "common/status.h"
#include "server/stereo/patchmatch.h"
#include "server/stereo/sgbm.h"

namespace holo {

struct StereoRoiOptions {
  // Off: every frame is matched whole.
  bool enabled = true;
  // The capture volume (world frame, metres): a vertical cylinder of
  // `volume_radius_m` around the z axis, from `volume_min_z_m` above the
  // floor (z = 0; the floor's own stereo noise, ~2 cm at 3 m, stays below)
  // to `volume_max_z_m`. The defaults cover the studio's capture area (the
  // person at the centre, props within 1 m; walls at 3.3 m).
  float volume_radius_m = 1.6f;
  float volume_min_z_m = 0.08f;
  float volume_max_z_m = 2.5f;
  // Margin around the previous foreground: the distance a body part moves at
  // `max_speed_mps` in the time since that frame (3 m/s: a brisk arm;
  // 10 cm per frame at 30 fps), as pixels at the nearest foreground depth,
  // plus `margin_px`.
  float max_speed_mps = 3.0f;
  int margin_px = 4;
  // The region as row spans around the foreground (true) or its bounding
  // box (false).
  bool row_spans = true;
  // Frame rate of the frame indices (elapsed time = index difference / fps).
  double fps = 30.0;
  // The whole image on frames where (frame index + full_phase) % full_every
  // == 0, and at least every full_every frames (1 = always). Sources give
  // each pod its own phase, so the pods' periodic full matches fall on
  // different frames (a frame set then costs about the same every frame).
  int full_every = 15;
  int full_phase = 0;
  // A gap longer than this since the previous frame: the whole image.
  double max_gap_s = 0.5;
  // Foreground pixels are sampled every `sample_step` pixels; a sample
  // counts with at least `min_neighbours` of its 8 grid neighbours in the
  // volume too, and a column or row counts towards the box with at least
  // `min_line_samples` such samples (mismatches inside the volume, thin
  // streaks on the floor, do not stretch the box).
  int sample_step = 2;
  int min_neighbours = 5;
  int min_vertical_run = 4;
  int min_group_samples = 24;
  int min_line_samples = 2;
  // The foreground within this many pixels of a region edge (that is not
  // the image's) touches it: the box, or any sample in a vertical run of at
  // least `touch_min_run` samples (a person entering across the edge).
  int touch_px = 2;
  int touch_min_run = 8;
  // See StereoRoiPolicy::max_disparity; < 0: no limit in regions either.
  float disparity_margin_px = 2.0f;
  // When the whole pair is due, Match searches it with OpenCV's SGBM
  // (sgbm.h, ~1/20 of PatchMatch's CPU for a whole pair) for the
  // foreground, then runs PatchMatch only around what it found (with the
  // margin for two frames' motion: SGBM's outline is a few pixels off
  // PatchMatch's, and with one frame's a studio pod's person touched the
  // region's edge), starting afresh there (not from the last planes; SGBM
  // searches the matcher's disparity range), and gives 0 elsewhere; with
  // nothing found, no PatchMatch at all and 0 everywhere. false: the whole
  // pair through PatchMatch, as before (2026-12-07), giving depth for the
  // whole image on those frames.
  bool search_with_sgbm = true;
  Status Check() const;
};

// One pod's region policy: Next() before matching a frame, Update() after.
class StereoRoiPolicy {
 public:
  // `pod` must be a stereo pod (its IR intrinsics, baseline and pose are
  // used); `options` must pass Check() (HOLO_CHECK otherwise).
  StereoRoiPolicy(const PodCalibration& pod, StereoRoiOptions options);

  // The region of the left IR image to match for frame `frame_index`
  // (the whole image when a full match is due, see above): its bounds; the
  // region itself is spans().
  ImageRect Next(int64_t frame_index);
  // The last Next's region.
  const RowSpans& spans() const { return spans_; }
  // The largest disparity the last Next's region can hold, to pass to
  // PatchMatchStereo::Compute: the previous frame's nearest foreground
  // brought nearer by the motion since (max_speed_mps × elapsed time) and
  // `disparity_margin_px` more; 3.0e38 (no limit) for the whole image. Only
  // the capture volume's content can be nearer than the person, and it is
  // the foreground (walls and floor behind the person are farther).
  float max_disparity() const { return max_disparity_; }
  // The disparity (left IR pixels, 0 = none) matched for `frame_index` in
  // `region`: its foreground becomes the next frame's region.
  void Update(int64_t frame_index, const RowSpans& region, const ImageFloat& disparity);
  void Update(int64_t frame_index, const ImageRect& region, const ImageFloat& disparity) {
    Update(frame_index, RowSpans::FromRect(region, width_, height_), disparity);
  }
  // Next, then `matcher` on that region with max_disparity(), then Update:
  // frame `frame_index`'s disparity in `disparity`; returns the region
  // PatchMatch matched. Where Next gives the whole pair and
  // options().search_with_sgbm is set, the pair is searched with SGBM
  // first and PatchMatch runs only around the foreground found (the
  // returned region; empty when none was found, `disparity` then all 0).
  StatusOr<RowSpans> Match(PatchMatchStereo* matcher, int64_t frame_index, const ImageGray8& left,
                           const ImageGray8& right, ImageFloat* disparity);
  // The full_phase of pod `pod` of `num_pods`: the rig's pods take turns for
  // their periodic full match.
  static int FullPhase(size_t pod, size_t num_pods, int full_every) {
    return num_pods == 0 ? 0 : static_cast<int>(pod * static_cast<size_t>(full_every) / num_pods);
  }

  // The last Update's foreground box (empty if none) and whether it asked
  // for a full match (empty, touching, ...).
  const ImageRect& foreground_box() const { return box_; }
  bool full_due() const { return full_due_; }
  // Whether the last Match searched the whole pair with SGBM.
  bool searched() const { return searched_; }
  const StereoRoiOptions& options() const { return options_; }

 private:
  PodCalibration pod_;
  StereoRoiOptions options_;
  int width_ = 0, height_ = 0;
  bool have_previous_ = false;
  bool full_due_ = true;
  int64_t previous_frame_ = 0, last_full_frame_ = 0;
  ImageRect box_;
  RowSpans spans_;
  std::vector<int> ext0_, ext1_;  // per sample row: the x extent of the last Update's foreground (pixels)
  float nearest_fg_m_ = 0;  // nearest foreground depth of the last Update
  float max_disparity_ = 3.0e38f;
  bool searched_ = false;
  // search_with_sgbm: the matcher, made on a policy's first search (a copy
  // of the policy makes its own: the matcher keeps scratch buffers), and
  // its disparity.
  struct LazySgbm {
    std::unique_ptr<SgbmStereo> matcher;
    LazySgbm() = default;
    LazySgbm(const LazySgbm&) {}
    LazySgbm& operator=(const LazySgbm&) {
      matcher.reset();
      return *this;
    }
    LazySgbm(LazySgbm&&) = default;
    LazySgbm& operator=(LazySgbm&&) = default;
  };
  LazySgbm sgbm_;
  ImageFloat search_;
  std::vector<uint8_t> fg_;  // scratch: foreground samples
  std::vector<float> zs_;    // ... and their depth
  std::vector<uint16_t> run_;  // ... and the length of their vertical run
  std::vector<uint8_t> core_;  // ... and which are core samples (2: grouped)
  std::vector<size_t> stack_, group_;

  // The region around the last Update's foreground for a frame `dt` seconds
  // later (Next's regions): spans_, max_disparity_; returns their bounds.
  ImageRect RegionAround(double dt);
};

}  // namespace holo
