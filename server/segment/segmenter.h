// Foreground segmentation per pod, after Holoportation (Orts-Escolano et al.,
// UIST 2016): a background model learned from empty-room frames, a unary term
// from colour (hue/saturation, robust to shadows) and depth (logistic in the
// depth difference), and a fully connected CRF solved by mean-field inference
// with a bilateral grid, so that mask edges follow image edges.
//
// Algorithm and measured figures: docs/segmentation.md.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "common/image.h"
#include "common/rgbd.h"
#include "common/rig.h"
#include "common/status.h"

namespace holo {

struct SegmenterOptions {
  // --- Depth term: log-odds L_d = (Δ − τ) / depth_sigma_m, Δ = background
  // depth − current depth (metres, > 0 when closer than the background).
  // Width of the logistic, metres.
  float depth_sigma_m = 0.05f;
  // τ = depth_margin_min_m + depth_margin_stddevs · σ_bg, where σ_bg is the
  // background pixel's depth standard deviation learned from the empty room
  // (it grows with z², like the sensor noise).
  float depth_margin_min_m = 0.02f;
  float depth_margin_stddevs = 3.0f;
  // Floor of σ_bg: sensor noise σ(z) = depth_noise_at_1m_m · z² (a few
  // empty-room samples underestimate the variance; 3 mm at 1 m is a typical
  // active-stereo / structured-light sensor).
  float depth_noise_at_1m_m = 0.003f;
  // Log-odds for a valid depth where no empty-room frame had one (wall
  // beyond the sensor range): something is there.
  float depth_appeared_logodds = 4.0f;
  // |L_d| is clamped to this.
  float depth_max_logodds = 6.0f;
  // Depth at a depth edge (a 4-neighbour differs by more than
  // `depth_edge_m`) is unreliable: sensors produce "flying pixels" with a
  // depth between the two surfaces there. Foreground evidence from such
  // pixels is capped at `depth_edge_max_logodds`, so colour decides.
  float depth_edge_m = 0.06f;
  float depth_edge_max_logodds = 2.0f;
  // The cap also holds within this many pixels of a depth edge, where the
  // edge is a 4-neighbour more than depth_edge_m away or with no depth
  // (0: only at the edge itself). For stereo depth: a window-based matcher
  // spreads the nearer surface's depth a few pixels past its edge (over the
  // background, or into the strip the other camera cannot see), so there
  // colour must decide (docs/stereo.md, "Stereo depth at the site").
  int depth_edge_band_px = 0;

  // --- Colour term on HSV: hue and saturation as the chroma vector
  // S·(cos H, sin H) of the hexcone, value V separately; L_c = colour_scale ·
  // (D − colour_threshold), D the distance to the background in standard
  // deviations.
  // Standard deviation of the chroma vector (S units, 0..1) added to the
  // learned one (the studio's colour has no sensor noise; a camera has).
  float chroma_sigma = 0.07f;
  // Standard deviation of V (0..1). Large: shadows and shading change V, not
  // H and S, so V counts little.
  float value_sigma = 0.35f;
  // Pixels darker than this (0..255, max channel) have unstable hue and
  // saturation: their chroma is shrunk towards grey by M / (M + dark_level).
  float dark_level = 24.0f;
  float colour_threshold = 2.5f;
  float colour_scale = 1.5f;
  // L_c is clamped to [−colour_bg_max_logodds, colour_max_logodds]. The
  // background side is weaker: a colour that differs from the background is
  // strong evidence of foreground, but a matching colour is weak evidence of
  // background (a grey object in front of a grey wall), so depth decides.
  float colour_max_logodds = 4.0f;
  float colour_bg_max_logodds = 2.0f;
  // Weights of the two terms in the unary log-odds, and a constant prior
  // (negative: background is more likely a priori).
  float depth_weight = 1.0f;
  float colour_weight = 1.0f;
  float prior_logodds = 0.0f;

  // --- Fully connected CRF (Potts, bilateral appearance kernel) solved by
  // `crf_iterations` mean-field updates: all but the last on the image
  // downsampled by `downsample` (1, 2 or 4), the last at full resolution
  // so mask edges follow image edges. The bilateral filter is a grid of
  // cell size `grid_spatial_px` (full-resolution pixels) × `grid_range`
  // (luma levels 0..255). 0 updates = unary only.
  int crf_iterations = 2;
  int downsample = 2;
  float grid_spatial_px = 4.0f;
  float grid_range = 16.0f;
  // Weight of the pairwise term in log-odds: each iteration uses
  // L + crf_weight · (2 q̄ − 1), q̄ the bilateral average of the foreground
  // probability around the pixel.
  float crf_weight = 3.0f;

  // Worker threads across pods (0 = hardware concurrency).
  int threads = 2;
  // The unary term eight pixels at a time with AVX2 where the CPU has it;
  // false: the portable path (the same result bit for bit; for tests).
  bool simd = true;

  // OK, or InvalidArgument naming the field and value.
  Status Check() const;
};

// Intermediate results of one pod, for inspection and tests.
struct SegmentDebug {
  ImageFloat unary_logodds;  // full resolution, > 0 = foreground
  ImageGray8 unary_mask;     // unary_logodds > 0
};

class Segmenter {
 public:
  // `rig` gives the pods (count, resolutions). `options` must pass Check()
  // (HOLO_CHECK otherwise; check untrusted options first). Pods whose depth
  // is not registered to colour are supported: colour is sampled into the
  // depth camera through the current depth.
  Segmenter(const Rig& rig, SegmenterOptions options);
  ~Segmenter();
  Segmenter(const Segmenter&) = delete;
  Segmenter& operator=(const Segmenter&) = delete;

  // Accumulates one empty-room frame set into the background model (per pod,
  // per pixel mean/variance of depth over valid samples and of HSV colour).
  // Call for every empty frame set, then FinishBackground(). InvalidArgument
  // on a pod count or image size mismatch with the rig.
  Status AddBackgroundFrame(const RgbdFrameSet& frames);
  // Turns the accumulated sums into the model. InvalidArgument if no frame
  // was added. Discards the sums; a new AddBackgroundFrame starts over.
  Status FinishBackground();
  bool has_background() const;

  // Fills frames->frames[i].mask (255 = foreground, depth camera resolution)
  // for every pod. InvalidArgument before FinishBackground() or on a pod
  // count / image size mismatch (nothing is written then). Reuses internal
  // buffers: no heap allocation per call in steady state (masks are resized
  // once). Runs pods in parallel on options.threads threads.
  Status Segment(RgbdFrameSet* frames);
  // Same, with the unary-only result of every pod in `debug` (resized to
  // the pod count).
  Status Segment(RgbdFrameSet* frames, std::vector<SegmentDebug>* debug);

  const SegmenterOptions& options() const { return options_; }

 private:
  struct Impl;
  SegmenterOptions options_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace holo
