// Image comparison metrics: PSNR, SSIM, depth error, mask overlap.
// Definitions: docs/metrics.md. Masks are ImageGray8, nonzero = inside. All
// functions fail with InvalidArgument on empty images, size mismatches, or a
// mask that selects nothing usable; the message names the sizes.
#pragma once

#include <cstddef>

#include "common/image.h"
#include "common/status.h"

namespace holo::metrics {

// PSNR reported when the images are identical (or the MSE is below
// 255² · 1e-10): a finite cap keeps JSON output and averages meaningful.
inline constexpr double kPsnrCapDb = 100.0;

// PSNR in dB = 10·log10(255² / MSE), MSE over every channel of every pixel
// (or of the pixels where `mask` is nonzero), capped at kPsnrCapDb.
// `mask` may be null (all pixels).
StatusOr<double> ComputePsnr(const ImageRgb8& a, const ImageRgb8& b, const ImageGray8* mask = nullptr);
StatusOr<double> ComputePsnr(const ImageGray8& a, const ImageGray8& b, const ImageGray8* mask = nullptr);

enum class SsimChannels {
  kLuma,            // SSIM of Y = 0.299 R + 0.587 G + 0.114 B (unrounded)
  kPerChannelMean,  // mean of the SSIM of R, G and B
};

struct SsimOptions {
  SsimChannels channels = SsimChannels::kLuma;
};

// SSIM (Wang, Bovik, Sheikh, Simoncelli 2004): 11×11 Gaussian window,
// σ = 1.5, K1 = 0.01, K2 = 0.03, L = 255, no downsampling. The SSIM map is
// evaluated at every pixel whose window lies fully inside the image ("valid"
// filtering, as in the reference MATLAB code) and averaged; with `mask`, the
// average is over those pixels where the mask is nonzero. 1 for identical
// images. Needs images of at least 11×11.
StatusOr<double> ComputeSsim(const ImageRgb8& a, const ImageRgb8& b, const ImageGray8* mask = nullptr,
                             const SsimOptions& options = {});
StatusOr<double> ComputeSsim(const ImageGray8& a, const ImageGray8& b, const ImageGray8* mask = nullptr);

struct DepthErrorStats {
  // Over pixels (inside the mask) where both depths are valid (nonzero), mm;
  // NaN if there is no such pixel.
  double mean_abs_error_mm = 0;
  double rmse_mm = 0;
  double mean_signed_error_mm = 0;  // estimate − truth (bias)
  double median_abs_error_mm = 0;
  // Fraction of truth-valid pixels (inside the mask) where the estimate is
  // valid too.
  double fraction_valid = 0;
  size_t num_truth_valid = 0;  // truth-valid pixels inside the mask
  size_t num_compared = 0;     // both valid
};

// Compares `estimate` against `truth` (uint16 mm, 0 = invalid). `mask` may be
// null (all pixels). InvalidArgument also if no truth pixel inside the mask
// is valid.
StatusOr<DepthErrorStats> ComputeDepthError(const ImageDepth16& estimate, const ImageDepth16& truth,
                                            const ImageGray8* mask = nullptr);

struct MaskOverlap {
  // |P ∩ T| / |P ∪ T|; 1 if both masks are empty.
  double iou = 0;
  // |P ∩ T| / |P|; 1 if both empty, 0 if only P is empty.
  double precision = 0;
  // |P ∩ T| / |T|; 1 if both empty, 0 if only T is empty.
  double recall = 0;
  size_t intersection = 0, union_count = 0, predicted_count = 0, truth_count = 0;
};

// Overlap of a `predicted` foreground mask with the `truth` mask (nonzero =
// foreground).
StatusOr<MaskOverlap> CompareMasks(const ImageGray8& predicted, const ImageGray8& truth);

}  // namespace holo::metrics
