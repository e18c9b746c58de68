// Baseline for the segmentation benchmark: OpenCV's BackgroundSubtractorMOG2
// on the colour image of each pod, trained on the same empty-room frames as
// Segmenter and frozen afterwards (learning rate 0). Colour only: MOG2 knows
// nothing of depth. No OpenCV type appears in this interface.
#pragma once

#include <memory>

#include "common/rgbd.h"
#include "common/status.h"

namespace holo {

struct Mog2Options {
  // Gaussian mixture parameters (OpenCV defaults: history 500, threshold 16).
  int history = 500;
  double var_threshold = 16.0;
  // MOG2's shadow detection: shadow pixels are reported as background.
  bool detect_shadows = true;
  Status Check() const;
};

class Mog2Segmenter {
 public:
  Mog2Segmenter(int num_pods, Mog2Options options);
  ~Mog2Segmenter();
  Mog2Segmenter(const Mog2Segmenter&) = delete;
  Mog2Segmenter& operator=(const Mog2Segmenter&) = delete;

  // Trains every pod's model on one empty-room frame set. InvalidArgument
  // on a pod count mismatch or a colour size that changed.
  Status AddBackgroundFrame(const RgbdFrameSet& frames);
  // Fills frames->frames[i].mask (255 = foreground, colour camera
  // resolution; equal to the depth camera for registered pods) without
  // updating the model. InvalidArgument before any background frame.
  Status Segment(RgbdFrameSet* frames);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace holo
