// Colour calibration between pods: a per-pod affine colour map (3×4) into the
// colour space of a reference pod, estimated without ground truth from the
// static background seen by two pods (empty-room frames): pod A's depth puts
// a pixel's surface point into pod B's image, B's depth confirms that the
// point is visible there, and the colour pairs of all such points between
// every two pods are fitted jointly (all maps at once, reference fixed) by
// robust (Huber IRLS) least squares — so pods facing away from the
// reference are calibrated through their neighbours.
//
// Method and measured figures: docs/segmentation.md.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "common/rgbd.h"
#include "common/rig.h"
#include "common/status.h"

namespace holo {

struct ColorCalibration {
  int reference_pod = 0;
  // Per pod: [r g b]_ref = M · [r g b 1]_pod, colours 0..255. Identity (with
  // a zero offset column) for the reference pod.
  std::vector<Eigen::Matrix<float, 3, 4>> pod_to_reference;

  // Identity maps for `num_pods` pods.
  static ColorCalibration Identity(int num_pods, int reference_pod = 0);
  // Maps every pod's colour image in place (rounded, clamped to 0..255),
  // with a 256-entry table per (output, input) channel pair: a few lookups
  // per pixel. The calibration must have one map per pod of `frames`
  // (HOLO_CHECK: it was made for this rig).
  void Apply(RgbdFrameSet* frames) const;
  // Maps one pixel of pod `pod` (no clamping).
  Eigen::Vector3f Map(int pod, const Eigen::Vector3f& rgb) const;
};

struct ColorCalibrationOptions {
  // A point of pod A and its projection into the reference pod are the same
  // surface if the reference depth agrees within this many metres plus
  // `depth_tolerance_rel` × depth.
  float depth_tolerance_m = 0.02f;
  float depth_tolerance_rel = 0.01f;
  // Pixels whose 3×3 neighbourhood has a depth step above this (metres) or
  // a colour range above `max_local_colour_range` (0..255, any channel) are
  // skipped: near edges and in strong texture a small misregistration mixes
  // colours.
  float max_local_depth_step_m = 0.05f;
  int max_local_colour_range = 40;
  // Colours at or beyond these levels in either pod are clipped, not affine.
  int min_level = 3;
  int max_level = 252;
  // Sample every `stride`-th pixel of pod A in x and y.
  int stride = 2;
  // Pod pairs with fewer correspondences than this are ignored; a pod with
  // fewer than `min_pairs` in all, or not connected to the reference through
  // used pairs → InvalidArgument.
  int min_edge_pairs = 50;
  int min_pairs = 200;
  // Huber threshold on the residual (0..255 units) and IRLS iterations.
  float huber_delta = 4.0f;
  int irls_iterations = 8;
  // Fit a full 3×4 map (true) or a per-channel gain and offset (false, the
  // diagonal of the 3×4 map). The colours of a room's walls and floor are
  // nearly collinear in RGB, so the cross-channel terms of a full map are
  // poorly determined by background pairs and extrapolate badly (measured:
  // docs/segmentation.md); use the full map only with a colourful scene or
  // chart.
  bool full_matrix = false;
  Status Check() const;
};

// Correspondence statistics of one pod, for reports and tests.
struct ColorCalibrationStats {
  // Per pod, over the colour pairs it shares with any other pod (a pair
  // counts for both of its pods): their number, and the mean |c_a − c_b|
  // (0..255, mean over channels) before and after mapping both.
  std::vector<int> pairs;
  std::vector<double> residual_before;
  std::vector<double> residual_after;
};

// Estimates maps from every pod to `reference_pod` from `frames` (frame sets
// of the static empty room; the per-pixel average over them is used, so
// several frames reduce depth noise). InvalidArgument on an empty `frames`,
// a bad reference index, a pod count or image size mismatch with `rig`, or
// when a pod shares fewer than options.min_pairs usable surface points with
// the other pods or is not connected to the reference through them (the
// message names the pod and the count). `stats` may be null.
StatusOr<ColorCalibration> EstimateColorCalibration(const Rig& rig, const std::vector<RgbdFrameSet>& frames,
                                                    int reference_pod, const ColorCalibrationOptions& options = {},
                                                    ColorCalibrationStats* stats = nullptr);

}  // namespace holo
