// One interface for every RGB-D input: the synthetic studio, recorded
// datasets on disk, and (later) pods over the network. Pipelines and tests
// take a FrameSource so the same code runs on all of them.
#pragma once

#include <cstdint>

#include "common/rgbd.h"
#include "common/rig.h"
#include "common/status.h"

namespace holo {

class FrameSource {
 public:
  virtual ~FrameSource() = default;
  // Calibration of the pods whose frames Next() returns.
  virtual const Rig& rig() const = 0;
  // Fills `out` with the next synchronized frame set, reusing its buffers.
  // OutOfRange at the end of a finite source; other codes on errors (a
  // missing or malformed file names the file).
  virtual Status Next(RgbdFrameSet* out) = 0;
  // Number of frame sets, or -1 for an endless live source.
  virtual int64_t num_frames() const = 0;
  // Restarts at frame `index`; OutOfRange past the end.
  virtual Status Seek(int64_t index) = 0;
  // Passes over the next `n` frame sets (a live site that fell behind skips
  // the frames it could not take). The default reads and discards them.
  virtual Status Skip(int64_t n) {
    RgbdFrameSet discard;
    for (int64_t i = 0; i < n; ++i) HOLO_RETURN_IF_ERROR(Next(&discard));
    return OkStatus();
  }
};

}  // namespace holo
