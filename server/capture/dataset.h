// Multi-pod RGB-D recordings on disk (layout in docs/dataset-format.md):
//
//   DIR/rig.yaml                     calibration of the pods
//   DIR/frames.csv                   frame,pod,timestamp_us   (one row per pod per frame)
//   DIR/pod<k>/color/<frame:06>.png  (or .jpg)   RGB8, color camera
//   DIR/pod<k>/depth/<frame:06>.png  uint16 PNG, millimetres, 0 = invalid
//   DIR/pod<k>/mask/<frame:06>.png   optional 8-bit foreground mask
//   DIR/groundtruth/...              optional (studio exports): noise-free
//                                    depth, exact masks, mesh_<frame:06>.ply
//
// The reader is safe on untrusted folders: every problem is a Status naming
// the file and what is wrong.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "common/frame_source.h"
#include "common/mesh.h"
#include "common/rgbd.h"
#include "common/rig.h"
#include "common/status.h"

namespace holo {

struct DatasetWriterOptions {
  bool color_jpeg = false;  // JPEG instead of PNG for color
  int jpeg_quality = 95;
};

class DatasetWriter {
 public:
  // Creates `dir` (and parents), writes rig.yaml. Fails if `dir` already holds a dataset.
  static StatusOr<std::unique_ptr<DatasetWriter>> Create(const std::string& dir, const Rig& rig,
                                                         DatasetWriterOptions options = {});
  ~DatasetWriter();
  // Appends one frame set (frames in pod order, sizes as in the rig).
  Status Write(const RgbdFrameSet& frames);
  // Ground truth beside the recording for frame `frame_index`.
  Status WriteGroundTruth(int64_t frame_index, const std::vector<ImageDepth16>& depth,
                          const std::vector<ImageGray8>& masks, const Mesh* mesh);
  // Flushes frames.csv. Called by the destructor too.
  Status Close();

 private:
  DatasetWriter() = default;
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

class DatasetReader final : public FrameSource {
 public:
  // Opens and validates the index (rig.yaml, frames.csv); images are checked
  // as they are read.
  static StatusOr<std::unique_ptr<DatasetReader>> Open(const std::string& dir);
  ~DatasetReader() override;

  const Rig& rig() const override;
  Status Next(RgbdFrameSet* out) override;
  int64_t num_frames() const override;
  Status Seek(int64_t index) override;
  // Reads frame set `index` directly.
  Status Read(int64_t index, RgbdFrameSet* out) const;
  // Ground truth, if the dataset has it (NotFound otherwise).
  bool has_ground_truth() const;
  StatusOr<Mesh> ReadGroundTruthMesh(int64_t index) const;
  Status ReadGroundTruthDepth(int64_t index, std::vector<ImageDepth16>* depth, std::vector<ImageGray8>* masks) const;

 private:
  DatasetReader() = default;
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace holo
