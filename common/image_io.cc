#include "common/image_io.h"

#include <algorithm>
#include <cctype>
#include <climits>
#include <cstring>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "common/file_util.h"

namespace holo {
namespace {

std::string LowerExtension(const std::string& path) {
  const size_t slash = path.find_last_of('/');
  const size_t dot = path.find_last_of('.');
  if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return "";
  std::string ext = path.substr(dot);
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  return ext;
}

std::string DepthName(int cv_depth) {
  switch (cv_depth) {
    case CV_8U: return "8-bit";
    case CV_8S: return "8-bit signed";
    case CV_16U: return "16-bit";
    case CV_16S: return "16-bit signed";
    case CV_32S: return "32-bit integer";
    case CV_32F: return "32-bit float";
    case CV_64F: return "64-bit float";
    default: return "unknown bit depth";
  }
}

// "8-bit" for one channel, "16-bit 3-channel" otherwise.
std::string Describe(const cv::Mat& m) {
  std::string s = DepthName(m.depth());
  if (m.channels() != 1) {
    s += ' ';
    s += std::to_string(m.channels());
    s += "-channel";
  }
  return s;
}

bool IsPng(const uint8_t* data, size_t size) {
  static const uint8_t kMagic[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  return size >= 8 && std::memcmp(data, kMagic, 8) == 0;
}

// Larger images are refused before decoding (an untrusted header must not
// make us allocate gigabytes): 64 Mpixel, e.g. 8192x8192.
constexpr uint64_t kMaxImagePixels = uint64_t{1} << 26;

uint32_t BigEndian32(const uint8_t* p) {
  return (uint32_t{p[0]} << 24) | (uint32_t{p[1]} << 16) | (uint32_t{p[2]} << 8) | uint32_t{p[3]};
}

// Decodes any format imgcodecs knows, unchanged (no channel or depth conversion).
Status DecodeUnchanged(const uint8_t* data, size_t size, const std::string& name, cv::Mat* out) {
  if (size == 0) return DataLoss(name + ": empty file");
  if (size > static_cast<size_t>(INT_MAX)) return DataLoss(name + ": file too large to decode");
  // PNG: signature, then the IHDR chunk (length, "IHDR", width, height).
  if (IsPng(data, size) && size >= 24) {
    const uint64_t w = BigEndian32(data + 16), h = BigEndian32(data + 20);
    if (w * h > kMaxImagePixels)
      return DataLoss(name + ": PNG header says " + std::to_string(w) + "x" + std::to_string(h) +
                      ", more than the limit of " + std::to_string(kMaxImagePixels) + " pixels");
  }
  try {
    // imdecode only reads from the buffer; the const_cast is for cv::Mat's constructor.
    const cv::Mat buf(1, static_cast<int>(size), CV_8U, const_cast<uint8_t*>(data));
    *out = cv::imdecode(buf, cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception& e) {
    return DataLoss(name + ": cannot decode image: " + e.what());
  }
  if (out->empty() || out->dims != 2) return DataLoss(name + ": cannot decode image (corrupt or unsupported format)");
  return OkStatus();
}

template <typename T, int C>
void CopyFromMat(const cv::Mat& m, Image<T, C>* out) {
  out->Resize(m.cols, m.rows);
  const size_t row_bytes = static_cast<size_t>(m.cols) * C * sizeof(T);
  for (int y = 0; y < m.rows; ++y) std::memcpy(out->row(y), m.ptr(y), row_bytes);
}

template <typename T, int C>
cv::Mat WrapImage(const Image<T, C>& image, int cv_type) {
  // Borrowed view for encoding only; imencode does not write to it.
  return cv::Mat(image.height(), image.width(), cv_type, const_cast<T*>(image.data()));
}

Status Encode(const std::string& path, const cv::Mat& mat, const ImageWriteOptions& options, bool allow_jpeg) {
  HOLO_RETURN_IF_ERROR(options.Check().WithContext(path));
  if (mat.empty()) return InvalidArgument(path + ": cannot write an empty image");
  const std::string ext = LowerExtension(path);
  std::vector<int> params;
  if (ext == ".png") {
    params = {cv::IMWRITE_PNG_COMPRESSION, options.png_compression};
  } else if (allow_jpeg && (ext == ".jpg" || ext == ".jpeg")) {
    params = {cv::IMWRITE_JPEG_QUALITY, options.jpeg_quality};
  } else {
    return InvalidArgument(path + ": unsupported extension '" + ext + "' (" +
                           (allow_jpeg ? "use .png, .jpg or .jpeg)" : "use .png)"));
  }
  std::vector<uint8_t> bytes;
  try {
    if (!cv::imencode(ext, mat, bytes, params)) return Internal(path + ": image encoding failed");
  } catch (const cv::Exception& e) {
    return Internal(path + ": image encoding failed: " + e.what());
  }
  return WriteStringToFile(path, std::string(bytes.begin(), bytes.end()));
}

template <typename T, int C>
StatusOr<Image<T, C>> ReadToValue(const std::string& path, Status (*read)(const std::string&, Image<T, C>*)) {
  Image<T, C> image;
  HOLO_RETURN_IF_ERROR(read(path, &image));
  return image;
}

// Reads the whole file; NotFound names the path.
StatusOr<std::string> ReadImageFile(const std::string& path) {
  if (!FileExists(path)) return NotFound(path + ": file not found");
  return ReadFileToString(path);
}

}  // namespace

Status ImageWriteOptions::Check() const {
  if (jpeg_quality < 1 || jpeg_quality > 100)
    return InvalidArgument("jpeg_quality must be in 1..100, got " + std::to_string(jpeg_quality));
  if (png_compression < 0 || png_compression > 9)
    return InvalidArgument("png_compression must be in 0..9, got " + std::to_string(png_compression));
  return OkStatus();
}

Status DecodeImageRgb8(const uint8_t* data, size_t size, const std::string& name, ImageRgb8* out) {
  cv::Mat m;
  HOLO_RETURN_IF_ERROR(DecodeUnchanged(data, size, name, &m));
  if (m.depth() != CV_8U) return DataLoss(name + ": color must be an 8-bit image, got " + Describe(m));
  cv::Mat rgb;
  switch (m.channels()) {
    case 1: cv::cvtColor(m, rgb, cv::COLOR_GRAY2RGB); break;
    case 3: cv::cvtColor(m, rgb, cv::COLOR_BGR2RGB); break;
    case 4: cv::cvtColor(m, rgb, cv::COLOR_BGRA2RGB); break;
    default: return DataLoss(name + ": color must have 1, 3 or 4 channels, got " + Describe(m));
  }
  CopyFromMat(rgb, out);
  return OkStatus();
}

Status DecodeDepth16(const uint8_t* data, size_t size, const std::string& name, ImageDepth16* out) {
  if (!IsPng(data, size)) return DataLoss(name + ": depth must be a 16-bit single-channel PNG, got a non-PNG file");
  cv::Mat m;
  HOLO_RETURN_IF_ERROR(DecodeUnchanged(data, size, name, &m));
  if (m.depth() != CV_16U || m.channels() != 1)
    return DataLoss(name + ": depth must be a 16-bit single-channel PNG, got " + Describe(m));
  CopyFromMat(m, out);
  return OkStatus();
}

Status DecodeMask8(const uint8_t* data, size_t size, const std::string& name, ImageGray8* out) {
  if (!IsPng(data, size)) return DataLoss(name + ": mask must be an 8-bit single-channel PNG, got a non-PNG file");
  cv::Mat m;
  HOLO_RETURN_IF_ERROR(DecodeUnchanged(data, size, name, &m));
  if (m.depth() != CV_8U || m.channels() != 1)
    return DataLoss(name + ": mask must be an 8-bit single-channel PNG, got " + Describe(m));
  CopyFromMat(m, out);
  return OkStatus();
}

Status ReadImageRgb8(const std::string& path, ImageRgb8* out) {
  HOLO_ASSIGN_OR_RETURN(const std::string bytes, ReadImageFile(path));
  return DecodeImageRgb8(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size(), path, out);
}

Status ReadDepth16(const std::string& path, ImageDepth16* out) {
  HOLO_ASSIGN_OR_RETURN(const std::string bytes, ReadImageFile(path));
  return DecodeDepth16(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size(), path, out);
}

Status ReadMask8(const std::string& path, ImageGray8* out) {
  HOLO_ASSIGN_OR_RETURN(const std::string bytes, ReadImageFile(path));
  return DecodeMask8(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size(), path, out);
}

StatusOr<ImageRgb8> ReadImageRgb8(const std::string& path) { return ReadToValue<uint8_t, 3>(path, &ReadImageRgb8); }
StatusOr<ImageDepth16> ReadDepth16(const std::string& path) { return ReadToValue<uint16_t, 1>(path, &ReadDepth16); }
StatusOr<ImageGray8> ReadMask8(const std::string& path) { return ReadToValue<uint8_t, 1>(path, &ReadMask8); }

Status WriteImageRgb8(const std::string& path, const ImageRgb8& image, const ImageWriteOptions& options) {
  if (image.empty()) return InvalidArgument(path + ": cannot write an empty image");
  cv::Mat bgr;
  cv::cvtColor(WrapImage(image, CV_8UC3), bgr, cv::COLOR_RGB2BGR);
  return Encode(path, bgr, options, /*allow_jpeg=*/true);
}

Status WriteDepth16(const std::string& path, const ImageDepth16& depth, const ImageWriteOptions& options) {
  if (depth.empty()) return InvalidArgument(path + ": cannot write an empty image");
  return Encode(path, WrapImage(depth, CV_16UC1), options, /*allow_jpeg=*/false);
}

Status WriteMask8(const std::string& path, const ImageGray8& mask, const ImageWriteOptions& options) {
  if (mask.empty()) return InvalidArgument(path + ": cannot write an empty image");
  return Encode(path, WrapImage(mask, CV_8UC1), options, /*allow_jpeg=*/false);
}

}  // namespace holo
