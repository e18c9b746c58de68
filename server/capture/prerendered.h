// Frames rendered into memory before a run and handed out by copy, as a
// live source: a stand-in for pods that deliver frames into memory, so that
// the site's acquire stage costs what a live site pays (a copy), not the
// synthetic studio's rendering (which is not the site's work).
//
// In loop mode the source never ends: frame sets k = 0, 1, 2, ... carry
// frame_index k and the content of stored frame LoopContent(k, n), which
// walks the stored frames forward and back (0 … n−1, n−2 … 1, 0 …), so the
// motion has no jump where the loop turns (temporal tracking sees ordinary
// frames).
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "common/frame_source.h"
#include "common/rgbd.h"
#include "common/rig.h"

namespace holo {

class SyntheticStudio;

// Index of the stored frame shown as frame `k` of a ping-pong loop over `n`.
int64_t LoopContent(int64_t k, int64_t n);

class PrerenderedSource final : public FrameSource {
 public:
  PrerenderedSource(const Rig& rig, std::shared_ptr<const std::vector<RgbdFrameSet>> frames, bool loop);
  // Renders frames 0 … count−1 of `studio` (progress on stderr unless quiet).
  static StatusOr<std::unique_ptr<PrerenderedSource>> Render(SyntheticStudio& studio, int count, bool loop,
                                                             bool quiet = true);
  // The next `count` frame sets of `source` (any source: the studio, or the
  // studio through stereo matching), with their frame indices.
  static StatusOr<std::unique_ptr<PrerenderedSource>> Record(FrameSource& source, int count, bool loop,
                                                             bool quiet = true);

  const Rig& rig() const override { return rig_; }
  Status Next(RgbdFrameSet* out) override;
  int64_t num_frames() const override { return loop_ ? -1 : static_cast<int64_t>(frames_->size()); }
  Status Seek(int64_t index) override;
  Status Skip(int64_t n) override;

  // The stored frame sets (frame_index = the studio's frame number).
  const std::vector<RgbdFrameSet>& frames() const { return *frames_; }
  // Studio frame number whose content frame set `k` carries.
  int64_t ContentFrame(int64_t k) const;

 private:
  Rig rig_;
  std::shared_ptr<const std::vector<RgbdFrameSet>> frames_;
  bool loop_ = false;
  int64_t next_ = 0;
};

}  // namespace holo
