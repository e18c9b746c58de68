#include "server/capture/dataset.h"

#include <charconv>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string_view>
#include <system_error>

#include "common/file_util.h"
#include "common/image_io.h"

namespace holo {
namespace {

constexpr const char* kFramesHeader = "frame,pod,timestamp_us";
// frames.csv larger than this is refused before reading it (~13 M rows).
constexpr uintmax_t kMaxFramesCsvBytes = 256u << 20;
// Frame sets per dataset: 10 M sets is 92 hours at 30 fps.
constexpr size_t kMaxFrameSets = 10'000'000;

std::string FrameName(int64_t frame) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%06lld", static_cast<long long>(frame));
  return buf;
}

std::string PodDir(const std::string& dir, size_t pod) { return dir + "/pod" + std::to_string(pod); }
std::string GroundTruthPodDir(const std::string& dir, size_t pod) {
  return dir + "/groundtruth/pod" + std::to_string(pod);
}
std::string GroundTruthMeshPath(const std::string& dir, int64_t frame) {
  return dir + "/groundtruth/mesh_" + FrameName(frame) + ".ply";
}

std::string SizeString(int w, int h) { return std::to_string(w) + "x" + std::to_string(h); }

// OK when `image` is `w`×`h`; otherwise InvalidArgument/DataLoss naming `what`.
template <typename T, int C>
Status CheckSize(const Image<T, C>& image, int w, int h, const std::string& what, const std::string& expected_from,
                 StatusCode code) {
  if (image.width() == w && image.height() == h) return OkStatus();
  return Status(code, what + ": image is " + SizeString(image.width(), image.height()) + ", " + expected_from +
                          " says " + SizeString(w, h));
}

std::string_view Trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t' || s.front() == '\r')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r')) s.remove_suffix(1);
  return s;
}

bool ParseInt64(std::string_view s, int64_t* out) {
  s = Trim(s);
  if (s.empty()) return false;
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), *out);
  return ec == std::errc() && end == s.data() + s.size();
}

}  // namespace

// ---------------------------------------------------------------------------
// Writer

struct DatasetWriter::Impl {
  std::string dir;
  Rig rig;
  DatasetWriterOptions options;
  std::ofstream csv;
  int64_t last_frame = -1;
  bool closed = false;
};

StatusOr<std::unique_ptr<DatasetWriter>> DatasetWriter::Create(const std::string& dir, const Rig& rig,
                                                               DatasetWriterOptions options) {
  HOLO_RETURN_IF_ERROR(rig.Check().WithContext("rig"));
  if (options.jpeg_quality < 1 || options.jpeg_quality > 100)
    return InvalidArgument("jpeg_quality must be in 1..100, got " + std::to_string(options.jpeg_quality));
  if (FileExists(dir + "/rig.yaml") || FileExists(dir + "/frames.csv"))
    return InvalidArgument(dir + ": already holds a dataset (rig.yaml or frames.csv exists)");
  HOLO_RETURN_IF_ERROR(MakeDirs(dir));
  for (size_t k = 0; k < rig.pods.size(); ++k) {
    HOLO_RETURN_IF_ERROR(MakeDirs(PodDir(dir, k) + "/color"));
    HOLO_RETURN_IF_ERROR(MakeDirs(PodDir(dir, k) + "/depth"));
  }
  HOLO_RETURN_IF_ERROR(SaveRig(dir + "/rig.yaml", rig));
  std::unique_ptr<DatasetWriter> w(new DatasetWriter());
  w->impl_ = std::make_unique<Impl>();
  Impl& impl = *w->impl_;
  impl.dir = dir;
  impl.rig = rig;
  impl.options = options;
  const std::string csv_path = dir + "/frames.csv";
  impl.csv.open(csv_path, std::ios::out | std::ios::trunc);
  if (!impl.csv) return Unavailable(csv_path + ": cannot open for writing");
  impl.csv << kFramesHeader << '\n';
  impl.csv.flush();
  if (!impl.csv) return Unavailable(csv_path + ": write failed");
  return w;
}

DatasetWriter::~DatasetWriter() {
  if (impl_) (void)Close();
}

Status DatasetWriter::Write(const RgbdFrameSet& set) {
  Impl& impl = *impl_;
  if (impl.closed) return InvalidArgument(impl.dir + ": dataset writer is closed");
  const auto& pods = impl.rig.pods;
  const std::string at = impl.dir + ": frame " + std::to_string(set.frame_index);
  if (set.frame_index < 0) return InvalidArgument(at + ": frame_index must be >= 0");
  if (set.frame_index <= impl.last_frame)
    return InvalidArgument(at + ": frame numbers must increase, last written " + std::to_string(impl.last_frame));
  if (set.frames.size() != pods.size())
    return InvalidArgument(at + ": has " + std::to_string(set.frames.size()) + " pod frames, rig has " +
                           std::to_string(pods.size()) + " pods");
  for (size_t k = 0; k < pods.size(); ++k) {
    const RgbdFrame& f = set.frames[k];
    const std::string pod = at + " pod " + std::to_string(k);
    if (f.pod_id != static_cast<int>(k))
      return InvalidArgument(pod + ": frames must be in pod order, got pod_id " + std::to_string(f.pod_id));
    HOLO_RETURN_IF_ERROR(CheckSize(f.color, pods[k].color.width, pods[k].color.height, pod + " color", "rig",
                                   StatusCode::kInvalidArgument));
    HOLO_RETURN_IF_ERROR(CheckSize(f.depth, pods[k].depth.width, pods[k].depth.height, pod + " depth", "rig",
                                   StatusCode::kInvalidArgument));
    if (!f.mask.empty())
      HOLO_RETURN_IF_ERROR(CheckSize(f.mask, pods[k].depth.width, pods[k].depth.height, pod + " mask", "rig depth",
                                     StatusCode::kInvalidArgument));
  }
  // Images first, index rows last: frames.csv never names a frame whose files are not complete.
  const std::string name = FrameName(set.frame_index);
  ImageWriteOptions wo;
  wo.jpeg_quality = impl.options.jpeg_quality;
  for (size_t k = 0; k < pods.size(); ++k) {
    const RgbdFrame& f = set.frames[k];
    const std::string pd = PodDir(impl.dir, k);
    HOLO_RETURN_IF_ERROR(
        WriteImageRgb8(pd + "/color/" + name + (impl.options.color_jpeg ? ".jpg" : ".png"), f.color, wo));
    HOLO_RETURN_IF_ERROR(WriteDepth16(pd + "/depth/" + name + ".png", f.depth, wo));
    if (!f.mask.empty()) {
      HOLO_RETURN_IF_ERROR(MakeDirs(pd + "/mask"));
      HOLO_RETURN_IF_ERROR(WriteMask8(pd + "/mask/" + name + ".png", f.mask, wo));
    }
  }
  for (size_t k = 0; k < pods.size(); ++k)
    impl.csv << set.frame_index << ',' << k << ',' << set.frames[k].timestamp_us << '\n';
  impl.csv.flush();
  if (!impl.csv) return Unavailable(impl.dir + "/frames.csv: write failed");
  impl.last_frame = set.frame_index;
  return OkStatus();
}

Status DatasetWriter::WriteGroundTruth(int64_t frame_index, const std::vector<ImageDepth16>& depth,
                                       const std::vector<ImageGray8>& masks, const Mesh* mesh) {
  Impl& impl = *impl_;
  const auto& pods = impl.rig.pods;
  const std::string at = impl.dir + ": ground truth of frame " + std::to_string(frame_index);
  if (frame_index < 0) return InvalidArgument(at + ": frame_index must be >= 0");
  if (!depth.empty() && depth.size() != pods.size())
    return InvalidArgument(at + ": " + std::to_string(depth.size()) + " depth images for " +
                           std::to_string(pods.size()) + " pods");
  if (!masks.empty() && masks.size() != pods.size())
    return InvalidArgument(at + ": " + std::to_string(masks.size()) + " masks for " + std::to_string(pods.size()) +
                           " pods");
  for (size_t k = 0; k < depth.size(); ++k)
    HOLO_RETURN_IF_ERROR(CheckSize(depth[k], pods[k].depth.width, pods[k].depth.height,
                                   at + " pod " + std::to_string(k) + " depth", "rig", StatusCode::kInvalidArgument));
  for (size_t k = 0; k < masks.size(); ++k)
    HOLO_RETURN_IF_ERROR(CheckSize(masks[k], pods[k].depth.width, pods[k].depth.height,
                                   at + " pod " + std::to_string(k) + " mask", "rig", StatusCode::kInvalidArgument));
  const std::string name = FrameName(frame_index);
  for (size_t k = 0; k < depth.size(); ++k) {
    const std::string d = GroundTruthPodDir(impl.dir, k) + "/depth";
    HOLO_RETURN_IF_ERROR(MakeDirs(d));
    HOLO_RETURN_IF_ERROR(WriteDepth16(d + "/" + name + ".png", depth[k]));
  }
  for (size_t k = 0; k < masks.size(); ++k) {
    const std::string d = GroundTruthPodDir(impl.dir, k) + "/mask";
    HOLO_RETURN_IF_ERROR(MakeDirs(d));
    HOLO_RETURN_IF_ERROR(WriteMask8(d + "/" + name + ".png", masks[k]));
  }
  if (mesh != nullptr) {
    HOLO_RETURN_IF_ERROR(MakeDirs(impl.dir + "/groundtruth"));
    HOLO_RETURN_IF_ERROR(WritePly(GroundTruthMeshPath(impl.dir, frame_index), *mesh));
  }
  return OkStatus();
}

Status DatasetWriter::Close() {
  Impl& impl = *impl_;
  if (impl.closed) return OkStatus();
  impl.closed = true;
  impl.csv.flush();
  const bool good = static_cast<bool>(impl.csv);
  impl.csv.close();
  if (!good) return Unavailable(impl.dir + "/frames.csv: write failed");
  return OkStatus();
}

// ---------------------------------------------------------------------------
// Reader

namespace {

struct FrameEntry {
  int64_t frame = 0;
  std::vector<int64_t> timestamps_us;  // one per pod
};

// Parses frames.csv (see dataset.h); errors are "<path>:<line>: problem".
Status ParseFramesCsv(const std::string& path, const std::string& text, size_t num_pods,
                      std::vector<FrameEntry>* entries) {
  entries->clear();
  size_t pos = 0;
  int64_t line_no = 0;
  bool have_header = false;
  std::vector<bool> seen;
  int64_t group_line = 0;
  auto finish_group = [&]() -> Status {
    if (entries->empty()) return OkStatus();
    for (size_t k = 0; k < num_pods; ++k)
      if (!seen[k])
        return DataLoss(path + ":" + std::to_string(group_line) + ": frame " + std::to_string(entries->back().frame) +
                        " has no row for pod " + std::to_string(k) + " (every frame needs all " +
                        std::to_string(num_pods) + " pods)");
    return OkStatus();
  };
  while (pos < text.size()) {
    size_t eol = text.find('\n', pos);
    if (eol == std::string::npos) eol = text.size();
    const std::string_view line = Trim(std::string_view(text).substr(pos, eol - pos));
    pos = eol + 1;
    ++line_no;
    const std::string at = path + ":" + std::to_string(line_no) + ": ";
    if (!have_header) {
      if (line != kFramesHeader)
        return DataLoss(at + "expected header '" + kFramesHeader + "', got '" + std::string(line.substr(0, 80)) + "'");
      have_header = true;
      continue;
    }
    if (line.empty()) continue;
    int64_t v[3];
    size_t start = 0;
    int n = 0;
    for (;;) {
      const size_t comma = line.find(',', start);
      const std::string_view field = line.substr(start, comma == std::string_view::npos ? line.npos : comma - start);
      if (n < 3 && !ParseInt64(field, &v[n]))
        return DataLoss(at + "field " + std::to_string(n + 1) + " is not an integer: '" +
                        std::string(field.substr(0, 40)) + "'");
      ++n;
      if (comma == std::string_view::npos) break;
      start = comma + 1;
    }
    if (n != 3) return DataLoss(at + "expected 3 fields (frame,pod,timestamp_us), got " + std::to_string(n));
    const int64_t frame = v[0], pod = v[1], ts = v[2];
    if (frame < 0) return DataLoss(at + "frame must be >= 0, got " + std::to_string(frame));
    if (pod < 0 || pod >= static_cast<int64_t>(num_pods))
      return DataLoss(at + "pod " + std::to_string(pod) + " is not in the rig (pods 0.." +
                      std::to_string(num_pods - 1) + ")");
    if (entries->empty() || frame != entries->back().frame) {
      if (!entries->empty() && frame < entries->back().frame)
        return DataLoss(at + "frame " + std::to_string(frame) + " after frame " +
                        std::to_string(entries->back().frame) + ": frame numbers must increase");
      HOLO_RETURN_IF_ERROR(finish_group());
      if (entries->size() >= kMaxFrameSets)
        return DataLoss(at + "more than " + std::to_string(kMaxFrameSets) + " frame sets");
      entries->push_back({frame, std::vector<int64_t>(num_pods, 0)});
      seen.assign(num_pods, false);
      group_line = line_no;
    }
    if (seen[static_cast<size_t>(pod)])
      return DataLoss(at + "duplicate row for frame " + std::to_string(frame) + " pod " + std::to_string(pod));
    seen[static_cast<size_t>(pod)] = true;
    entries->back().timestamps_us[static_cast<size_t>(pod)] = ts;
  }
  if (!have_header) return DataLoss(path + ": empty file, expected header '" + std::string(kFramesHeader) + "'");
  return finish_group();
}

}  // namespace

struct DatasetReader::Impl {
  std::string dir;
  Rig rig;
  std::vector<FrameEntry> entries;
  int64_t cursor = 0;
};

StatusOr<std::unique_ptr<DatasetReader>> DatasetReader::Open(const std::string& dir) {
  std::error_code ec;
  if (!std::filesystem::is_directory(dir, ec)) return NotFound(dir + ": not a directory");
  auto impl = std::make_unique<Impl>();
  impl->dir = dir;
  const std::string rig_path = dir + "/rig.yaml";
  if (!FileExists(rig_path)) return NotFound(rig_path + ": file not found (not a dataset folder?)");
  HOLO_ASSIGN_OR_RETURN(impl->rig, LoadRig(rig_path));
  HOLO_RETURN_IF_ERROR(impl->rig.Check().WithContext(rig_path));

  const std::string csv_path = dir + "/frames.csv";
  if (!FileExists(csv_path)) return NotFound(csv_path + ": file not found");
  const uintmax_t size = std::filesystem::file_size(csv_path, ec);
  if (ec) return Unavailable(csv_path + ": cannot stat: " + ec.message());
  if (size > kMaxFramesCsvBytes)
    return DataLoss(csv_path + ": " + std::to_string(size) + " bytes, more than the limit of " +
                    std::to_string(kMaxFramesCsvBytes));
  HOLO_ASSIGN_OR_RETURN(const std::string text, ReadFileToString(csv_path));
  HOLO_RETURN_IF_ERROR(ParseFramesCsv(csv_path, text, impl->rig.pods.size(), &impl->entries));

  std::unique_ptr<DatasetReader> r(new DatasetReader());
  r->impl_ = std::move(impl);
  return r;
}

DatasetReader::~DatasetReader() = default;

const Rig& DatasetReader::rig() const { return impl_->rig; }
int64_t DatasetReader::num_frames() const { return static_cast<int64_t>(impl_->entries.size()); }

Status DatasetReader::Seek(int64_t index) {
  if (index < 0 || index >= num_frames())
    return OutOfRange(impl_->dir + ": seek to frame set " + std::to_string(index) + " of " +
                      std::to_string(num_frames()));
  impl_->cursor = index;
  return OkStatus();
}

Status DatasetReader::Next(RgbdFrameSet* out) {
  if (impl_->cursor >= num_frames())
    return OutOfRange(impl_->dir + ": end of dataset (" + std::to_string(num_frames()) + " frame sets)");
  // Move past the frame set even if it fails, so a caller may skip a damaged one.
  const int64_t index = impl_->cursor++;
  return Read(index, out);
}

Status DatasetReader::Read(int64_t index, RgbdFrameSet* out) const {
  const Impl& impl = *impl_;
  if (index < 0 || index >= num_frames())
    return OutOfRange(impl.dir + ": frame set " + std::to_string(index) + " of " + std::to_string(num_frames()));
  const FrameEntry& e = impl.entries[static_cast<size_t>(index)];
  const std::string name = FrameName(e.frame);
  const auto& pods = impl.rig.pods;
  out->frame_index = e.frame;
  out->frames.resize(pods.size());
  for (size_t k = 0; k < pods.size(); ++k) {
    RgbdFrame& f = out->frames[k];
    f.pod_id = static_cast<int>(k);
    f.timestamp_us = e.timestamps_us[k];
    const std::string pd = PodDir(impl.dir, k);
    const std::string at = "rig.yaml pods[" + std::to_string(k) + "]";

    std::string color_path = pd + "/color/" + name + ".png";
    if (!FileExists(color_path) && FileExists(pd + "/color/" + name + ".jpg")) color_path = pd + "/color/" + name + ".jpg";
    if (!FileExists(color_path)) return NotFound(color_path + ": file not found (nor .jpg)");
    HOLO_RETURN_IF_ERROR(ReadImageRgb8(color_path, &f.color));
    HOLO_RETURN_IF_ERROR(
        CheckSize(f.color, pods[k].color.width, pods[k].color.height, color_path, at + ".color", StatusCode::kDataLoss));

    const std::string depth_path = pd + "/depth/" + name + ".png";
    HOLO_RETURN_IF_ERROR(ReadDepth16(depth_path, &f.depth));
    HOLO_RETURN_IF_ERROR(
        CheckSize(f.depth, pods[k].depth.width, pods[k].depth.height, depth_path, at + ".depth", StatusCode::kDataLoss));

    const std::string mask_path = pd + "/mask/" + name + ".png";
    if (FileExists(mask_path)) {
      HOLO_RETURN_IF_ERROR(ReadMask8(mask_path, &f.mask));
      HOLO_RETURN_IF_ERROR(CheckSize(f.mask, pods[k].depth.width, pods[k].depth.height, mask_path, at + ".depth",
                                     StatusCode::kDataLoss));
    } else {
      f.mask.Resize(0, 0);
    }
  }
  return OkStatus();
}

bool DatasetReader::has_ground_truth() const {
  std::error_code ec;
  return std::filesystem::is_directory(impl_->dir + "/groundtruth", ec);
}

StatusOr<Mesh> DatasetReader::ReadGroundTruthMesh(int64_t index) const {
  if (index < 0 || index >= num_frames())
    return OutOfRange(impl_->dir + ": frame set " + std::to_string(index) + " of " + std::to_string(num_frames()));
  const std::string path = GroundTruthMeshPath(impl_->dir, impl_->entries[static_cast<size_t>(index)].frame);
  if (!FileExists(path)) return NotFound(path + ": file not found");
  return ReadPly(path);
}

Status DatasetReader::ReadGroundTruthDepth(int64_t index, std::vector<ImageDepth16>* depth,
                                           std::vector<ImageGray8>* masks) const {
  const Impl& impl = *impl_;
  if (index < 0 || index >= num_frames())
    return OutOfRange(impl.dir + ": frame set " + std::to_string(index) + " of " + std::to_string(num_frames()));
  const std::string name = FrameName(impl.entries[static_cast<size_t>(index)].frame);
  const auto& pods = impl.rig.pods;
  if (depth != nullptr) depth->resize(pods.size());
  if (masks != nullptr) masks->resize(pods.size());
  for (size_t k = 0; k < pods.size(); ++k) {
    const std::string gd = GroundTruthPodDir(impl.dir, k);
    const std::string at = "rig.yaml pods[" + std::to_string(k) + "].depth";
    if (depth != nullptr) {
      const std::string p = gd + "/depth/" + name + ".png";
      HOLO_RETURN_IF_ERROR(ReadDepth16(p, &(*depth)[k]));
      HOLO_RETURN_IF_ERROR(
          CheckSize((*depth)[k], pods[k].depth.width, pods[k].depth.height, p, at, StatusCode::kDataLoss));
    }
    if (masks != nullptr) {
      const std::string p = gd + "/mask/" + name + ".png";
      if (FileExists(p)) {
        HOLO_RETURN_IF_ERROR(ReadMask8(p, &(*masks)[k]));
        HOLO_RETURN_IF_ERROR(
            CheckSize((*masks)[k], pods[k].depth.width, pods[k].depth.height, p, at, StatusCode::kDataLoss));
      } else {
        (*masks)[k].Resize(0, 0);
      }
    }
  }
  return OkStatus();
}

}  // namespace holo
