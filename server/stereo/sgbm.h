// OpenCV's semi-global block matcher (StereoSGBM, 3-way mode) behind the
// project's image types: the peer the stereo bench measures PatchMatch
// against, and the region policy's cheap search of a whole pair for the
// person (stereo_roi.h: a whole S8-QVGA pair in ~10 CPU-ms, against ~200 for
// PatchMatch). OpenCV's matcher is used as it is: it is the library made for
// this and the reference the issue compares with.
#pragma once

#include <memory>

#include "common/image.h"

namespace holo {

class SgbmStereo {
 public:
  // Disparities searched: [floor(min_d), floor(min_d) + n) with n the range
  // rounded up to a multiple of 16 (at least 16); 5×5 blocks, the smoothness
  // penalties OpenCV's documentation suggests for 8-bit grey images
  // (8·25 and 32·25), uniqueness 10 %, speckle filter 100 px / 2 px.
  SgbmStereo(float min_d, float max_d);
  ~SgbmStereo();
  SgbmStereo(const SgbmStereo&) = delete;
  SgbmStereo& operator=(const SgbmStereo&) = delete;

  // Disparity of every left pixel (pixels, 1/16 px steps), 0 where SGBM
  // gives none. The two images must have the same size (checked: an empty
  // result otherwise). OpenCV's matcher leaves the first min + range
  // columns without disparity (it takes only matches that stay inside the
  // right image over the whole range); both images are padded on the left
  // with that many black columns so that those columns get one too (on the
  // studio's S8-QVGA pairs that took SGBM's bad-2px from 24.8 to 5.0 %, on
  // Middlebury Aloe from 32.3 to 16.8 %; docs/stereo.md).
  void Compute(const ImageGray8& left, const ImageGray8& right, ImageFloat* disparity);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace holo
