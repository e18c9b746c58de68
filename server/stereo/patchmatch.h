// Slanted-plane PatchMatch stereo (Bleyer, Rhemann, Rother, BMVC 2011) on the
// CPU, for a rectified pair (rows aligned, disparity = x_left − x_right ≥ 0).
//
// Every pixel of both views holds a plane d(x, y) = a·x + b·y + c in
// disparity space. Planes start random; each iteration, for the left then the
// right view: view propagation (the other view's planes, converted, offered
// to the pixels they land on), a horizontal sweep (each pixel tries the plane
// of the pixel before it in the row; rows run in parallel), a vertical sweep
// (the pixel above or below; blocks of columns in parallel), each followed by
// random refinement of the pixel's disparity and normal with a shrinking
// range. Sweep directions alternate between iterations (where the planes
// start from a coarse level or the last frame, the right view only takes view
// propagation and the horizontal sweep without refinement:
// PatchMatchOptions::light_right_view). Then a dense last pass moves each
// left plane along d in a window of adjacent pixels
// (PatchMatchOptions::final_window_step). Last, a left-right consistency
// check drops pixels whose two views disagree.
//
// Matching cost of a plane: a sparse window (8 columns × window_rows rows,
// `window_step` pixels apart) of truncated absolute differences of intensity
// and x gradient, each sample weighted by its intensity similarity to the
// centre pixel (1 / (1 + (ΔI/γ)²), an adaptive support weight), the other
// view sampled with linear interpolation at the plane's sub-pixel disparity.
// The 8 columns are one AVX2 vector (runtime dispatch; a scalar path runs the
// same arithmetic elsewhere); the other view's samples of a window row come
// from loads and in-register permutes when they span at most 24 pixels (the
// usual planes), from gathers otherwise. Random numbers come from a counter-based hash
// of (seed, pixel, pass): results do not depend on the thread count.
//
// Region of interest: Compute can be restricted to a rectangle of the left
// image (the site needs depth only where the person is; server/stereo/
// stereo_roi.h chooses the rectangle). Every step then runs inside it: the
// left view's planes, sweeps and refinement only in the rectangle, the right
// view's in the rectangle widened to the left by the disparity range (where
// the rectangle's pixels can match), view propagation between the two, the
// coarse level in the halved rectangle (one coarse pixel wider), and the
// left-right check. Costs still read the whole images (a window at the
// rectangle's edge samples the pixels beyond it), so a pixel's cost for a
// given plane is the full run's; the results differ from a full run's only
// because propagation starts at the rectangle's edges instead of the
// image's (figures in docs/stereo.md). The whole image as the rectangle
// gives the full run's result bit for bit. The region can also be row spans
// (RowSpans: per row, one run of pixels), shaped to the person rather than
// boxed: every step then runs on each row's span (the right view's widened
// to the left by the disparity range), the coarse level on the halved
// spans, and vertical propagation only between pixels both inside them; a
// rectangle is the special case (the rectangle overloads go through it).
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "common/image.h"
#include "common/status.h"

namespace holo {

class WorkerPool;

struct PatchMatchOptions {
  // Disparity search range, pixels.
  float min_disparity = 0.0f;
  float max_disparity = 64.0f;
  // Window: 8 columns × window_rows rows (odd), samples window_step apart.
  int window_rows = 5;
  int window_step = 2;
  // Propagation iterations (each: both views, horizontal and vertical sweeps).
  int iterations = 3;
  // Coarse to fine: the pair at half resolution first (with `iterations`,
  // recursively for more levels), then `fine_iterations` at this resolution
  // starting from its planes, the random refinement's range starting at
  // 2^-fine_refine_start of the first level's. 0 = one level. A level is
  // skipped when the half-size image would be under 16×8. On the studio's
  // IR pairs one level takes half the time and bad-2px from 21 to 13 %
  // (the coarse window spans four times the area, which the faint speckle
  // on far walls needs); docs/stereo.md has the figures.
  int coarse_levels = 1;
  int fine_iterations = 1;
  int fine_refine_start = 4;
  // Frames in sequence (one matcher per camera pair): a Compute on a region
  // (not the whole image) that lies mostly (≥ temporal_min_overlap of its
  // area) inside the last Compute's starts from the last result's planes
  // instead of the coarse level or random ones (pixels outside it from the
  // nearest inside), then runs `temporal_iterations` with the refinement's
  // range starting at 2^-temporal_refine_start and
  // `temporal_refine_per_sweep` candidates per sweep. Otherwise (the first frame, a new image size, a
  // region that moved or grew beyond the last, the whole image) it runs as
  // above. The scene moves little between frames at 30 fps, so the last
  // planes are a far better start than random ones; the region policy's
  // whole-pair frames (periodic, after a gap, when the person touches the
  // region's edge) run the full algorithm and so refresh the planes.
  // On the studio's S8-QVGA pairs in the site's regions (docs/stereo.md),
  // against the coarse level + one iteration (87 CPU-ms per pair, fused
  // mesh 9.3 mm from the direct-depth one): two iterations 67 CPU-ms and
  // 8.7 mm after a run of 10 frames (faster and closer: the default), one
  // iteration 38 CPU-ms and 10.7 mm.
  bool temporal = false;
  float temporal_min_overlap = 0.75f;
  int temporal_iterations = 2;
  int temporal_refine_start = 2;
  int temporal_refine_per_sweep = 1;
  // A temporal Compute leaves alone the pixels (of both views) that were
  // inside the last Compute's region and whose cost inputs have not changed
  // since it: the largest |I − I_last| over the pixel's window, averaged
  // with the same over its match's window in the other view, at most
  // `temporal_still` times the view's noise level (the median of that
  // change outside the region's bounds, where nothing the region follows
  // moves). The level starts at 0 and rises by at most 20 % + 0.25 grey
  // levels per Compute (a camera's noise is reached in ~10 frames), so a
  // view that moves as a whole (a light switched on, a knocked camera) is
  // matched again rather than left with old planes, unless it keeps moving
  // long enough to lift the level (then until the next whole pair). No
  // sweep, refinement or dense pass visits the pixels left alone; they
  // still offer their planes to their neighbours. On the studio's S8-QVGA
  // pairs (docs/stereo.md, "Leaving still pixels alone") 1.0 leaves the
  // site's masks, mesh and novel view as good (IoU −0.002, +0.08 dB), but
  // its CPU per frame did not drop measurably in alternated 40-frame runs
  // (604 against 611 CPU-ms): off by default until it does. The mean change
  // instead of the largest lost 0.016 of IoU (an edge moving a pixel
  // changes few samples, a lot). 0: every pixel is visited.
  float temporal_still = 0.0f;
  // Where the planes start from the coarse level's or the last Compute's (not
  // random ones), the right view takes only the left's planes (view
  // propagation) and its row neighbour's: no random refinement, no vertical
  // sweep. The right view is there for the left's view propagation and the
  // left-right check, and the left view's planes it receives are already
  // refined. On the studio's S8-QVGA pairs this cut a region's pair from the
  // last planes by about a quarter (64 → 49 CPU-ms) and a whole pair by a
  // sixth, with bad-2px and the fused mesh unchanged or slightly better (the
  // whole Middlebury Aloe pair: 23.6 → 23.0 %, 5.0 → 4.2 CPU-s);
  // docs/stereo.md. false: both views alike (as before 2026-12-07).
  bool light_right_view = true;
  // A last pass over the left view with a denser window: samples
  // `final_window_step` pixels apart (0 = no such pass), each pixel's plane
  // moved along d only (its normal kept) to the minimum of a V through its
  // costs at d and d ± final_step_px (the best of the four planes kept). The
  // sparse window (15 × 9 pixels at window_step 2) spans a quarter of a torso
  // and more than an arm at 320×240: fitted to a convex body it lies behind
  // the surface, and every pod's depth comes out a few millimetres too far
  // (+4.5 mm on the studio's person, disparities −0.03 px). The dense 8 × 5
  // window halves its span. On the studio's S8-QVGA pairs (docs/stereo.md,
  // "A dense last pass") the fused person came 8.8 → 7.0 mm from the
  // direct-depth one for about a fifth more CPU per pair (a binary search
  // down to 1/32 px instead of the V: 7.3 mm for half more CPU; a parabola:
  // 7.4 mm), and Middlebury Aloe's bad-2px rose 23.0 → 23.5 % (SGBM 32.3).
  int final_window_step = 1;
  float final_step_px = 0.5f;
  // An edge pass after the dense pass (off by default; docs/stereo.md, "An
  // edge pass"). At depth edges (the planes `edge_probe_px` left, right,
  // above or below a pixel differ by more than `edge_min_jump` of its
  // disparity) each of those planes and the pixel's own is costed in the
  // dense window shifted ±`edge_shift_px` sideways, weighted by the pixel's
  // own intensity, and another plane replaces the pixel's when its best
  // window costs less than (1 − edge_margin) of the own plane's best. A
  // window straddling an edge is won by the side with the stronger texture
  // (the nearer surface: the projector's speckle is brighter there), which
  // spreads the nearer depth a few pixels past the edge; a window shifted
  // away from the edge sees one surface only. Measured on the studio's
  // S8-QVGA pairs with edge_shift_px 2: the site's mask IoU on stereo depth
  // 0.865 → 0.882, its mesh 9.75 → 9.42 mm from the direct-depth site's, but
  // the person's bad-2px 1.6 → 2.6 % (edge pixels of the person taken for
  // the wall) and ~20 % more CPU per pair, so it stays off. 0: off.
  int edge_shift_px = 0;
  int edge_probe_px = 6;
  float edge_min_jump = 0.08f;
  float edge_margin = 0.1f;
  // Random refinement candidates after each sweep, each with half the
  // perturbation range of the one before; the range keeps halving from
  // sweep to sweep (disparity ±range/4 at first, normal ±1).
  int refine_per_sweep = 2;
  // Cost: (1 − alpha)·min(|ΔI|, tau_color) + alpha·min(|Δ∂I/∂x|, tau_grad),
  // grey levels; support weight 1 / (1 + (ΔI/gamma)²).
  float alpha = 0.5f;
  float tau_color = 20.0f;
  float tau_grad = 6.0f;
  float gamma = 12.0f;
  // Steepest allowed plane: the normal's z component (in (x, y, d) space) at
  // least this (1 = fronto-parallel only).
  float min_normal_z = 0.6f;
  // Left-right check: largest |d_left − d_right| kept, pixels (< 0: no check).
  float lr_max_diff = 1.0f;
  // Threads (counting the caller); 0 = hardware concurrency.
  int threads = 0;
  uint64_t seed = 1;
  // Scalar cost path even where AVX2 exists (tests compare the two).
  bool force_scalar = false;
  // OK, or InvalidArgument naming the field.
  Status Check() const;
};

// A rectangle of pixels [x0, x1) × [y0, y1).
struct ImageRect {
  int x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  static ImageRect Full(int width, int height) { return {0, 0, width, height}; }
  bool empty() const { return x1 <= x0 || y1 <= y0; }
  int width() const { return empty() ? 0 : x1 - x0; }
  int height() const { return empty() ? 0 : y1 - y0; }
  int64_t area() const { return static_cast<int64_t>(width()) * height(); }
  bool Contains(int x, int y) const { return x >= x0 && x < x1 && y >= y0 && y < y1; }
  // This rectangle clipped to a width × height image.
  ImageRect Clipped(int width, int height) const;
  bool operator==(const ImageRect& o) const { return x0 == o.x0 && y0 == o.y0 && x1 == o.x1 && y1 == o.y1; }
};

// Per image row y, the pixels [x0[y], x1[y]) (none where x0[y] >= x1[y]): a
// region shaped to what it covers (the region policy's person with a margin
// around it, row by row) rather than its bounding box.
struct RowSpans {
  std::vector<int> x0, x1;
  // `rect` (clipped to width × height) as spans of a `height`-row image.
  static RowSpans FromRect(const ImageRect& rect, int width, int height);
  int rows() const { return static_cast<int>(x0.size()); }
  bool Contains(int x, int y) const {
    return y >= 0 && y < rows() && x >= x0[static_cast<size_t>(y)] && x < x1[static_cast<size_t>(y)];
  }
  // The smallest rectangle holding every span (empty if none).
  ImageRect Bounds() const;
  int64_t area() const;
  // Every row the whole of a width-pixel row.
  bool IsFull(int width) const;
  bool operator==(const RowSpans& o) const { return x0 == o.x0 && x1 == o.x1; }
};

class PatchMatchStereo {
 public:
  // `options` must pass Check() (HOLO_CHECK otherwise; use Create for untrusted values).
  explicit PatchMatchStereo(PatchMatchOptions options);
  static StatusOr<std::unique_ptr<PatchMatchStereo>> Create(PatchMatchOptions options);
  ~PatchMatchStereo();
  PatchMatchStereo(const PatchMatchStereo&) = delete;
  PatchMatchStereo& operator=(const PatchMatchStereo&) = delete;

  // Disparity of every left pixel, pixels (sub-pixel), 0 where the
  // left-right check or the search range rejects it. Reuses internal buffers
  // between calls. InvalidArgument if the images differ in size or are
  // smaller than 16×8.
  Status Compute(const ImageGray8& left, const ImageGray8& right, ImageFloat* disparity);
  // The same, disparities only inside `region` of the left image (clipped
  // to the image; 0 outside it). An empty region gives 0 everywhere and
  // does no matching. The full image as `region` equals Compute above.
  Status Compute(const ImageGray8& left, const ImageGray8& right, const ImageRect& region, ImageFloat* disparity);
  // The same with the search range's upper end lowered to `max_disparity`
  // for this call (clamped to [min_disparity + 2, options().max_disparity]):
  // the right view's region narrows with it. Where nothing in the region can
  // be nearer than a known depth (the region policy: the previous frame's
  // nearest foreground and the motion since), the right view need not reach
  // as far. Pixels whose true disparity is larger get none or a wrong one.
  Status Compute(const ImageGray8& left, const ImageGray8& right, const ImageRect& region, float max_disparity,
                 ImageFloat* disparity);
  // The same in row spans of the left image (`spans.rows()` must be the
  // image's height; spans are clipped to its width): every step runs only on
  // the spans' pixels (the right view's on each row's span widened to the
  // left by the disparity range), 0 elsewhere. Spans of a rectangle give the
  // rectangle's result bit for bit.
  Status Compute(const ImageGray8& left, const ImageGray8& right, const RowSpans& spans, float max_disparity,
                 ImageFloat* disparity);
  // The right view's region for a left region: widened to the left by the
  // largest disparity, [x0 − ⌈max_disparity⌉, x1), clipped to the image
  // (max_disparity < 0: the options').
  ImageRect RightRegion(const ImageRect& left_region, int width, int height, float max_disparity = -1.0f) const;
  // The right view's disparity of the last Compute (x_left − x_right, at
  // right pixels, 0 outside the right view's region), unfiltered.
  const ImageFloat& right_disparity() const;
  // True when the AVX2 cost path runs.
  bool uses_avx2() const;
  // True when the last Compute started from the planes of the one before
  // (PatchMatchOptions::temporal).
  bool last_was_temporal() const;
  // The next Compute starts afresh (the coarse level or random planes), not
  // from the last one's planes, whatever its region: the region policy's
  // search of a whole pair (stereo_roi.h) refreshes the planes this way.
  void ForgetLast();
  const PatchMatchOptions& options() const { return options_; }

 private:
  struct Impl;
  PatchMatchOptions options_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace holo
