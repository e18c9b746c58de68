// WAV reading and writing for the voice tools and tests.
#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>

#include "audio/spatializer.h"
#include "protocol/byte_io.h"

namespace holo::audio {
namespace {

void Put16(std::vector<uint8_t>& v, uint16_t x) {
  v.push_back(static_cast<uint8_t>(x & 0xFF));
  v.push_back(static_cast<uint8_t>(x >> 8));
}
void Put32(std::vector<uint8_t>& v, uint32_t x) {
  for (int i = 0; i < 4; ++i) v.push_back(static_cast<uint8_t>((x >> (8 * i)) & 0xFF));
}

}  // namespace

Status WriteStereoWav(const std::string& path, std::span<const float> interleaved, int sample_rate) {
  const uint32_t data_bytes = static_cast<uint32_t>(interleaved.size() * 2);
  std::vector<uint8_t> b;
  b.reserve(44 + data_bytes);
  b.insert(b.end(), {'R', 'I', 'F', 'F'});
  Put32(b, 36 + data_bytes);
  b.insert(b.end(), {'W', 'A', 'V', 'E', 'f', 'm', 't', ' '});
  Put32(b, 16);
  Put16(b, 1);
  Put16(b, 2);
  Put32(b, static_cast<uint32_t>(sample_rate));
  Put32(b, static_cast<uint32_t>(sample_rate) * 4);
  Put16(b, 4);
  Put16(b, 16);
  b.insert(b.end(), {'d', 'a', 't', 'a'});
  Put32(b, data_bytes);
  for (float f : interleaved) {
    const float c = std::fmax(-1.0f, std::fmin(1.0f, f));
    Put16(b, static_cast<uint16_t>(static_cast<int16_t>(std::lrint(c * 32767.0f))));
  }
  std::ofstream out(path, std::ios::binary);
  if (!out) return Unavailable("cannot write " + path);
  out.write(reinterpret_cast<const char*>(b.data()), static_cast<std::streamsize>(b.size()));
  if (!out) return Unavailable("write failed: " + path);
  return OkStatus();
}

StatusOr<std::vector<float>> ReadMonoWav(const std::string& path, int target_rate) {
  if (target_rate < 8000 || target_rate > 192000) return InvalidArgument("target_rate outside 8000..192000");
  std::ifstream in(path, std::ios::binary);
  if (!in) return NotFound("cannot open " + path);
  const std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  protocol::ByteReader r(bytes.data(), bytes.size());
  std::span<const uint8_t> tag;
  uint32_t riff_size = 0;
  HOLO_RETURN_IF_ERROR(r.View("wav.riff", 4, &tag));
  if (std::memcmp(tag.data(), "RIFF", 4) != 0) return DataLoss(path + ": not a RIFF file");
  HOLO_RETURN_IF_ERROR(r.U32("wav.riff_size", &riff_size));
  HOLO_RETURN_IF_ERROR(r.View("wav.wave", 4, &tag));
  if (std::memcmp(tag.data(), "WAVE", 4) != 0) return DataLoss(path + ": not a WAVE file");
  uint16_t format = 0, channels = 0, bits = 0;
  uint32_t rate = 0;
  bool have_fmt = false;
  std::span<const uint8_t> data;
  while (r.remaining() >= 8) {
    std::span<const uint8_t> id;
    uint32_t size = 0;
    HOLO_RETURN_IF_ERROR(r.View("wav.chunk_id", 4, &id));
    HOLO_RETURN_IF_ERROR(r.U32("wav.chunk_size", &size));
    std::span<const uint8_t> body;
    HOLO_RETURN_IF_ERROR(r.View("wav.chunk", std::min<size_t>(size, r.remaining()), &body));
    if (size % 2 == 1 && r.remaining() > 0) HOLO_RETURN_IF_ERROR(r.View("wav.pad", 1, &tag));
    if (std::memcmp(id.data(), "fmt ", 4) == 0) {
      protocol::ByteReader f(body);
      uint32_t byte_rate = 0;
      uint16_t align = 0;
      HOLO_RETURN_IF_ERROR(f.U16("wav.format", &format));
      HOLO_RETURN_IF_ERROR(f.U16("wav.channels", &channels));
      HOLO_RETURN_IF_ERROR(f.U32("wav.rate", &rate));
      HOLO_RETURN_IF_ERROR(f.U32("wav.byte_rate", &byte_rate));
      HOLO_RETURN_IF_ERROR(f.U16("wav.align", &align));
      HOLO_RETURN_IF_ERROR(f.U16("wav.bits", &bits));
      have_fmt = true;
    } else if (std::memcmp(id.data(), "data", 4) == 0) {
      data = body;
    }
  }
  if (!have_fmt) return DataLoss(path + ": no fmt chunk");
  const bool pcm16 = format == 1 && bits == 16;
  const bool f32 = format == 3 && bits == 32;
  if (!pcm16 && !f32) {
    return DataLoss(path + ": only 16-bit PCM or 32-bit float WAV, got format " + std::to_string(format) + " with " +
                    std::to_string(bits) + " bits");
  }
  if (channels < 1 || channels > 8) return DataLoss(path + ": channel count " + std::to_string(channels));
  if (rate < 1000 || rate > 384000) return DataLoss(path + ": sample rate " + std::to_string(rate));
  const size_t frame_bytes = static_cast<size_t>(channels) * (bits / 8);
  const size_t n = data.size() / frame_bytes;
  std::vector<float> mono(n, 0.0f);
  for (size_t i = 0; i < n; ++i) {
    float acc = 0.0f;
    for (int c = 0; c < channels; ++c) {
      const uint8_t* p = data.data() + i * frame_bytes + static_cast<size_t>(c) * (bits / 8);
      if (pcm16) {
        acc += static_cast<float>(static_cast<int16_t>(static_cast<uint16_t>(p[0] | (p[1] << 8)))) / 32768.0f;
      } else {
        float v = 0.0f;
        std::memcpy(&v, p, 4);
        acc += std::isfinite(v) ? v : 0.0f;
      }
    }
    mono[i] = acc / static_cast<float>(channels);
  }
  if (static_cast<int>(rate) == target_rate || mono.empty()) return mono;
  const double step = static_cast<double>(rate) / target_rate;
  const size_t m = static_cast<size_t>(static_cast<double>(n - 1) / step) + 1;
  std::vector<float> out(m);
  for (size_t i = 0; i < m; ++i) {
    const double pos = static_cast<double>(i) * step;
    const size_t k = static_cast<size_t>(pos);
    const float frac = static_cast<float>(pos - static_cast<double>(k));
    out[i] = k + 1 < n ? mono[k] * (1.0f - frac) + mono[k + 1] * frac : mono[k];
  }
  return out;
}

}  // namespace holo::audio
