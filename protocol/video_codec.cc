#include "protocol/video_codec.h"

#include <zstd.h>

#include <algorithm>
#include <cstring>
#include <mutex>
#include <string>

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavutil/dict.h>
#include <libavutil/frame.h>
#include <libavutil/imgutils.h>
#include <libavutil/log.h>
#include <libavutil/pixdesc.h>
}

#include "protocol/byte_io.h"
#include "protocol/ycc.h"

namespace holo::protocol {
namespace {

std::string AvError(int err) {
  char buf[AV_ERROR_MAX_STRING_SIZE] = {};
  av_strerror(err, buf, sizeof(buf));
  return buf;
}

// ------------------------------------------------------------ mask rows
// The same row format as C1's mask (PROTOCOL.md §8, "Mask rows"), over the
// whole image instead of a box.

void PutVarint(std::vector<uint8_t>* out, uint32_t v) {
  while (v >= 0x80) {
    out->push_back(static_cast<uint8_t>(v | 0x80));
    v >>= 7;
  }
  out->push_back(static_cast<uint8_t>(v));
}

bool GetVarint(const uint8_t*& p, const uint8_t* end, uint32_t* v) {
  uint64_t r = 0;
  for (int shift = 0; shift < 35; shift += 7) {
    if (p == end) return false;
    const uint8_t b = *p++;
    r |= uint64_t{b & 0x7fu} << shift;
    if (!(b & 0x80)) {
      if (r > 0xffffffffu) return false;
      *v = static_cast<uint32_t>(r);
      return true;
    }
  }
  return false;
}

uint32_t ZigZag(int32_t v) { return (static_cast<uint32_t>(v) << 1) ^ static_cast<uint32_t>(v >> 31); }
int64_t UnZigZag(uint32_t z) { return static_cast<int64_t>(z >> 1) ^ -static_cast<int64_t>(z & 1u); }

Status EncodeMask(const ImageGray8& mask, int w, int h, std::vector<uint8_t>* rle, std::vector<uint8_t>* out) {
  rle->clear();
  std::vector<uint32_t> prev, cur;
  for (int y = 0; y < h; ++y) {
    cur.clear();
    if (mask.empty()) {
      cur.push_back(0);
    } else {
      const uint8_t* m = mask.row(y);
      bool in = false;
      for (int x = 0; x < w; ++x) {
        if ((m[x] != 0) != in) {
          cur.push_back(static_cast<uint32_t>(x));
          in = !in;
        }
      }
    }
    if (cur.size() == prev.size()) {
      rle->push_back(0);
      for (size_t i = 0; i < cur.size(); ++i) {
        PutVarint(rle, ZigZag(static_cast<int32_t>(cur[i]) - static_cast<int32_t>(prev[i])));
      }
    } else {
      PutVarint(rle, static_cast<uint32_t>(cur.size() + 1));
      for (size_t i = 0; i < cur.size(); ++i) PutVarint(rle, i == 0 ? cur[0] : cur[i] - cur[i - 1] - 1);
    }
    std::swap(prev, cur);
  }
  thread_local std::unique_ptr<ZSTD_CCtx, size_t (*)(ZSTD_CCtx*)> zc(ZSTD_createCCtx(), ZSTD_freeCCtx);
  if (!zc) return Internal("zstd: cannot create a compression context");
  out->resize(ZSTD_compressBound(rle->size()));
  const size_t z = ZSTD_compressCCtx(zc.get(), out->data(), out->size(), rle->data(), rle->size(), 3);
  if (ZSTD_isError(z)) return Internal(std::string("zstd: ") + ZSTD_getErrorName(z));
  out->resize(z);
  return OkStatus();
}

Status DecodeMask(std::span<const uint8_t> zmask, int w, int h, std::vector<uint8_t>* rle, ImageGray8* mask) {
  const unsigned long long declared = ZSTD_getFrameContentSize(zmask.data(), zmask.size());
  const uint64_t bound = uint64_t(h) * (uint64_t(w) + 1) * 3;
  if (declared == ZSTD_CONTENTSIZE_ERROR || declared == ZSTD_CONTENTSIZE_UNKNOWN || declared > bound ||
      declared < static_cast<uint64_t>(h)) {
    return DataLoss("v1.mask: zstd frame size is missing or impossible for the image");
  }
  rle->resize(declared);
  thread_local std::unique_ptr<ZSTD_DCtx, size_t (*)(ZSTD_DCtx*)> zd(ZSTD_createDCtx(), ZSTD_freeDCtx);
  if (!zd) return Internal("zstd: cannot create a decompression context");
  const size_t got = ZSTD_decompressDCtx(zd.get(), rle->data(), rle->size(), zmask.data(), zmask.size());
  if (ZSTD_isError(got) || got != declared) return DataLoss("v1.mask: zstd data is corrupt");
  mask->Resize(w, h, 0);
  const uint8_t* p = rle->data();
  const uint8_t* end = p + rle->size();
  std::vector<uint32_t> prev, cur;
  for (int y = 0; y < h; ++y) {
    uint32_t head = 0;
    if (!GetVarint(p, end, &head)) return DataLoss("v1.mask: row " + Str(y) + " ends early");
    cur.clear();
    if (head == 0) {
      for (size_t i = 0; i < prev.size(); ++i) {
        uint32_t z = 0;
        if (!GetVarint(p, end, &z)) return DataLoss("v1.mask: row " + Str(y) + " ends early");
        const int64_t t = int64_t{prev[i]} + UnZigZag(z);
        if (t < 0 || t >= w || (i > 0 && t <= int64_t{cur.back()})) {
          return DataLoss("v1.mask: row " + Str(y) + " transition " + Str(i) + " out of order or outside the row");
        }
        cur.push_back(static_cast<uint32_t>(t));
      }
    } else {
      const uint32_t k = head - 1;
      if (k > static_cast<uint32_t>(w)) return DataLoss("v1.mask: row " + Str(y) + " has " + Str(k) + " transitions");
      int64_t t = -1;
      for (uint32_t i = 0; i < k; ++i) {
        uint32_t g = 0;
        if (!GetVarint(p, end, &g)) return DataLoss("v1.mask: row " + Str(y) + " ends early");
        t = (i == 0) ? int64_t{g} : t + int64_t{g} + 1;
        if (t >= w) return DataLoss("v1.mask: row " + Str(y) + " transition " + Str(i) + " outside the row");
        cur.push_back(static_cast<uint32_t>(t));
      }
    }
    uint8_t* m = mask->row(y);
    for (size_t i = 0; i < cur.size(); i += 2) {
      const uint32_t a = cur[i];
      const uint32_t b = i + 1 < cur.size() ? cur[i + 1] : static_cast<uint32_t>(w);
      std::memset(m + a, 255, b - a);
    }
    std::swap(prev, cur);
  }
  if (p != end) return DataLoss("v1.mask: " + Str(static_cast<uint64_t>(end - p)) + " bytes after the last row");
  return OkStatus();
}

// ------------------------------------------------------------ mask blocks
// The mask as context-modelled binary decisions through an adaptive binary
// range coder (PROTOCOL.md §8, "V1 mask, coded blocks"): first the type of
// every 16×16 block (empty, full, mixed), then, in raster order over the
// image, every pixel of a mixed block from its six causal neighbours
// (JBIG's and MPEG-4 shape coding's idea, written here for our format). On
// the site's masks of fused S8-VGA frames this takes 580 bytes per pod
// image against 1 147 for the row format above with zstd, for ~1 CPU-ms more
// per frame of 8 pods to decode (docs/codecs.md); the row format stays
// readable (blobs without kVideoFlagMaskBlocks).

constexpr int kMaskBlock = 16;
constexpr uint32_t kMaskProbBits = 12;
constexpr uint16_t kMaskProbInit = 1u << (kMaskProbBits - 1);
constexpr int kMaskAdapt = 4;  // probability update: p += (target − p) >> 4
constexpr int kMaskPixelContexts = 1 << 6;
constexpr int kMaskMixedContexts = 9;  // left block type × upper block type (0, 1, 2)
constexpr int kMaskFullContexts = 4;   // left block full × upper block full

// p: the probability of a 0, in 1/4096; stays within [15, 4081].
inline void AdaptBit(uint16_t* p, int bit) {
  if (bit) {
    *p = static_cast<uint16_t>(*p - (*p >> kMaskAdapt));
  } else {
    *p = static_cast<uint16_t>(*p + (((1u << kMaskProbBits) - *p) >> kMaskAdapt));
  }
}

// Range encoder with carry propagation: 32-bit range, bytes out most
// significant first; the first byte out is always 0.
class BitEncoder {
 public:
  explicit BitEncoder(std::vector<uint8_t>* out) : out_(out) { out_->clear(); }
  void Put(uint16_t* p, int bit) {
    const uint32_t bound = (range_ >> kMaskProbBits) * *p;
    if (bit) {
      low_ += bound;
      range_ -= bound;
    } else {
      range_ = bound;
    }
    AdaptBit(p, bit);
    while (range_ < (1u << 24)) {
      range_ <<= 8;
      ShiftLow();
    }
  }
  void Finish() {
    for (int i = 0; i < 5; ++i) ShiftLow();
  }

 private:
  void ShiftLow() {
    if (static_cast<uint32_t>(low_) < 0xFF000000u || (low_ >> 32) != 0) {
      const uint8_t carry = static_cast<uint8_t>(low_ >> 32);
      uint8_t temp = cache_;
      do {
        out_->push_back(static_cast<uint8_t>(temp + carry));
        temp = 0xFF;
      } while (--pending_ != 0);
      cache_ = static_cast<uint8_t>(static_cast<uint32_t>(low_) >> 24);
    }
    ++pending_;
    low_ = static_cast<uint32_t>(low_) << 8;
  }
  std::vector<uint8_t>* out_;
  uint64_t low_ = 0;
  uint32_t range_ = 0xFFFFFFFFu;
  uint8_t cache_ = 0;
  uint64_t pending_ = 1;
};

// Decodes what BitEncoder wrote. Safe on any bytes: past the end it reads
// zeros and counts them. The decoder reads exactly the bytes the encoder
// wrote (5 at the start, one per renormalisation, as the encoder shifts one
// out per renormalisation and 5 when it finishes), so any read past the end
// means the stream was cut (overrun) and any byte left over is refused.
class BitDecoder {
 public:
  explicit BitDecoder(std::span<const uint8_t> in) : in_(in) {
    for (int i = 0; i < 5; ++i) code_ = (code_ << 8) | Next();
  }
  int Get(uint16_t* p) {
    const uint32_t bound = (range_ >> kMaskProbBits) * *p;
    int bit;
    if (code_ < bound) {
      range_ = bound;
      bit = 0;
    } else {
      code_ -= bound;
      range_ -= bound;
      bit = 1;
    }
    AdaptBit(p, bit);
    while (range_ < (1u << 24)) {
      range_ <<= 8;
      code_ = (code_ << 8) | Next();
    }
    return bit;
  }
  bool overrun() const { return past_end_ > 0; }
  bool first_byte_zero() const { return !in_.empty() && in_[0] == 0; }
  size_t unread() const { return pos_ < in_.size() ? in_.size() - pos_ : 0; }

 private:
  uint32_t Next() {
    if (pos_ < in_.size()) return in_[pos_++];
    ++past_end_;
    return 0;
  }
  std::span<const uint8_t> in_;
  size_t pos_ = 0;
  uint32_t past_end_ = 0;
  uint32_t code_ = 0;
  uint32_t range_ = 0xFFFFFFFFu;
};

// The pixels x0..x1−1 of one row of a mixed block, each coded from its six
// causal neighbours (0 outside the image): context = (m[x−1] | m[x−2] << 1
// | m[x−3] << 2) | (u[x+1] | u[x] << 1 | u[x−1] << 2) << 3, m this row, u
// the row above (all 0 for the first row). `code(p, x)` codes or decodes
// pixel x with probability p and returns its bit; the context slides along.
template <typename Coder>
inline void CodeSpan(const uint8_t* row, const uint8_t* up, int x0, int x1, int w, uint16_t* probs, Coder&& code) {
  uint32_t cur = (x0 >= 1 && row[x0 - 1] ? 1u : 0u) | (x0 >= 2 && row[x0 - 2] ? 2u : 0u) | (x0 >= 3 && row[x0 - 3] ? 4u : 0u);
  uint32_t upc = (x0 + 1 < w && up[x0 + 1] ? 1u : 0u) | (up[x0] ? 2u : 0u) | (x0 >= 1 && up[x0 - 1] ? 4u : 0u);
  for (int x = x0; x < x1; ++x) {
    const uint32_t bit = static_cast<uint32_t>(code(&probs[cur | (upc << 3)], x));
    cur = ((cur << 1) | bit) & 7u;
    upc = ((upc << 1) | (x + 2 < w && up[x + 2] ? 1u : 0u)) & 7u;
  }
}

// Block types in raster order: 0 empty, 1 full, 2 mixed. A mixed block's
// context is (left type, upper type), 0 outside; a non-mixed one then codes
// full or not from (left full, upper full).
template <typename Coder>
void CodeBlockTypes(int bw, int bh, std::vector<uint8_t>* types, Coder&& code) {
  std::vector<uint16_t> mixed(kMaskMixedContexts, kMaskProbInit), full(kMaskFullContexts, kMaskProbInit);
  for (int by = 0; by < bh; ++by) {
    for (int bx = 0; bx < bw; ++bx) {
      const uint8_t left = bx > 0 ? (*types)[size_t(by) * bw + bx - 1] : 0;
      const uint8_t upper = by > 0 ? (*types)[size_t(by - 1) * bw + bx] : 0;
      uint8_t& t = (*types)[size_t(by) * bw + bx];
      const int is_mixed = code(&mixed[left * 3 + upper], t == 2 ? 1 : 0);
      if (is_mixed) {
        t = 2;
      } else {
        t = static_cast<uint8_t>(code(&full[(left == 1 ? 1 : 0) + (upper == 1 ? 2 : 0)], t == 1 ? 1 : 0));
      }
    }
  }
}

// One row of a block: whether it holds any foreground and whether it is all
// foreground, eight mask bytes at a time where the row is a whole block.
inline uint64_t Load8(const uint8_t* p) {
  uint64_t v;
  std::memcpy(&v, p, 8);
  return v;
}
inline bool HasZeroByte(uint64_t v) { return ((v - 0x0101010101010101ull) & ~v & 0x8080808080808080ull) != 0; }
inline void ScanBlockRow(const uint8_t* m, int n, bool* any, bool* all) {
  if (n == kMaskBlock) {
    const uint64_t a = Load8(m), b = Load8(m + 8);
    *any = *any || (a | b) != 0;
    *all = *all && !HasZeroByte(a) && !HasZeroByte(b);
    return;
  }
  for (int x = 0; x < n; ++x) {
    *any = *any || m[x] != 0;
    *all = *all && m[x] != 0;
  }
}

// The type of the block of `mask` with corner (x0, y0) and size bw × bh:
// 0 no foreground, 1 all foreground, 2 both.
inline uint8_t BlockType(const ImageGray8& mask, int x0, int y0, int bw, int bh) {
  bool any = false, all = true;
  for (int y = y0; y < y0 + bh && (all || !any); ++y) ScanBlockRow(mask.row(y) + x0, bw, &any, &all);
  return !any ? 0 : (all ? 1 : 2);
}

// The type of every 16×16 block of the image in raster order: 0 no
// foreground, 1 all foreground (every block when there is no mask), 2 both.
// The encoder classifies once per image: the mask coder and the window's
// placement both read the types.
void ClassifyMaskBlocks(const ImageGray8& mask, int w, int h, std::vector<uint8_t>* types) {
  const int bw = (w + kMaskBlock - 1) / kMaskBlock, bh = (h + kMaskBlock - 1) / kMaskBlock;
  types->assign(size_t(bw) * bh, 1);
  if (mask.empty()) return;
  for (int by = 0; by < bh; ++by) {
    for (int bx = 0; bx < bw; ++bx) {
      (*types)[size_t(by) * bw + bx] =
          BlockType(mask, bx * kMaskBlock, by * kMaskBlock, std::min(kMaskBlock, w - bx * kMaskBlock),
                    std::min(kMaskBlock, h - by * kMaskBlock));
    }
  }
}

// `types` from ClassifyMaskBlocks of the same mask; the coder's contexts
// update them in place to what it coded (the same values).
Status EncodeMaskBlocks(const ImageGray8& mask, int w, int h, std::vector<uint8_t>* types, std::vector<uint8_t>* out) {
  const int bw = (w + kMaskBlock - 1) / kMaskBlock, bh = (h + kMaskBlock - 1) / kMaskBlock;
  BitEncoder enc(out);
  CodeBlockTypes(bw, bh, types, [&](uint16_t* p, int bit) {
    enc.Put(p, bit);
    return bit;
  });
  std::vector<uint16_t> probs(kMaskPixelContexts, kMaskProbInit);
  const std::vector<uint8_t> zeros(size_t(w), 0);
  for (int y = 0; y < h && !mask.empty(); ++y) {
    const uint8_t* row = mask.row(y);
    const uint8_t* up = y > 0 ? mask.row(y - 1) : zeros.data();
    const uint8_t* brow = types->data() + size_t(y / kMaskBlock) * bw;
    for (int bx = 0; bx < bw; ++bx) {
      if (brow[bx] != 2) continue;
      CodeSpan(row, up, bx * kMaskBlock, std::min(w, (bx + 1) * kMaskBlock), w, probs.data(), [&](uint16_t* p, int x) {
        const int bit = row[x] != 0;
        enc.Put(p, bit);
        return bit;
      });
    }
  }
  enc.Finish();
  return OkStatus();
}

Status DecodeMaskBlocks(std::span<const uint8_t> data, int w, int h, std::vector<uint8_t>* types, ImageGray8* mask) {
  const int bw = (w + kMaskBlock - 1) / kMaskBlock, bh = (h + kMaskBlock - 1) / kMaskBlock;
  BitDecoder dec(data);
  if (!dec.first_byte_zero()) return DataLoss("v1.mask: coded blocks do not start with a zero byte");
  types->assign(size_t(bw) * bh, 0);
  CodeBlockTypes(bw, bh, types, [&](uint16_t* p, int) { return dec.Get(p); });
  // Row by row, blocks left to right: a full block's pixels are set before
  // the mixed block to its right reads them as context.
  mask->Resize(w, h, 0);
  std::vector<uint16_t> probs(kMaskPixelContexts, kMaskProbInit);
  const std::vector<uint8_t> zeros(size_t(w), 0);
  for (int y = 0; y < h; ++y) {
    uint8_t* row = mask->row(y);
    const uint8_t* up = y > 0 ? mask->row(y - 1) : zeros.data();
    const uint8_t* brow = types->data() + size_t(y / kMaskBlock) * bw;
    for (int bx = 0; bx < bw; ++bx) {
      const int x0 = bx * kMaskBlock, x1 = std::min(w, x0 + kMaskBlock);
      if (brow[bx] == 1) {
        std::memset(row + x0, 255, size_t(x1 - x0));
      } else if (brow[bx] == 2) {
        CodeSpan(row, up, x0, x1, w, probs.data(), [&](uint16_t* p, int x) {
          const int bit = dec.Get(p);
          row[x] = bit ? 255 : 0;
          return bit;
        });
      }
    }
    if (dec.overrun()) return DataLoss("v1.mask: coded blocks end early, at row " + Str(y));
  }
  if (dec.unread() > 0) return DataLoss("v1.mask: " + Str(dec.unread()) + " bytes after the coded blocks");
  return OkStatus();
}

// ------------------------------------------------------------ colour
// Full-range BT.601 (JPEG) YCbCr, 16-bit fixed point (protocol/ycc.h). Both
// ends are ours, so the range flag in the bitstream is informative only.

constexpr int kBlock = 16;
constexpr uint8_t kFlat = 128;

// Writes `image` as YCbCr 4:4:4 into three planes (`stride` bytes per row),
// filling the background: flat grey in blocks without foreground, the
// foreground continued along rows, then columns, in blocks with some.
// Only the window `win` of the image is written (plane pixel (0, 0) is image
// pixel (win.x, win.y)); its 16×16 blocks start at the window's corner.
void ConvertAndFill(const ImageRgb8& image, const ImageGray8& mask, const VideoWindow& win, uint8_t* const planes[3],
                    const int strides[3]) {
  const int w = win.w, h = win.h;
  for (int by = 0; by < h; by += kBlock) {
    const int bh = std::min(kBlock, h - by);
    for (int bx = 0; bx < w; bx += kBlock) {
      const int bw = std::min(kBlock, w - bx);
      const uint8_t type = mask.empty() ? 1 : BlockType(mask, win.x + bx, win.y + by, bw, bh);
      if (type == 0) {
        for (int c = 0; c < 3; ++c) {
          for (int y = by; y < by + bh; ++y) std::memset(planes[c] + size_t(y) * strides[c] + bx, kFlat, bw);
        }
        continue;
      }
      if (type == 1) {
        for (int y = by; y < by + bh; ++y) {
          RgbToYccRow(image.row(win.y + y) + size_t(win.x + bx) * 3, bw, planes[0] + size_t(y) * strides[0] + bx,
                      planes[1] + size_t(y) * strides[1] + bx, planes[2] + size_t(y) * strides[2] + bx);
        }
        continue;
      }
      bool row_has[kBlock] = {};
      for (int y = by; y < by + bh; ++y) {
        const uint8_t* src = image.row(win.y + y) + size_t(win.x + bx) * 3;
        const uint8_t* m = mask.empty() ? nullptr : mask.row(win.y + y) + win.x + bx;
        uint8_t* py = planes[0] + size_t(y) * strides[0] + bx;
        uint8_t* pu = planes[1] + size_t(y) * strides[1] + bx;
        uint8_t* pv = planes[2] + size_t(y) * strides[2] + bx;
        // The whole row converted, then its background overwritten.
        RgbToYccRow(src, bw, py, pu, pv);
        int first = -1, last = -1;
        for (int x = 0; x < bw; ++x) {
          if (!m || m[x]) {
            if (first < 0) first = x;
            last = x;
          } else if (last >= 0) {
            py[x] = py[last];
            pu[x] = pu[last];
            pv[x] = pv[last];
          }
        }
        if (first < 0) continue;
        row_has[y - by] = true;
        for (int x = 0; x < first; ++x) {
          py[x] = py[first];
          pu[x] = pu[first];
          pv[x] = pv[first];
        }
      }
      // Rows without foreground: copy the nearest row that has some (below first, then above).
      int src_row = -1;
      for (int j = 0; j < bh; ++j) {
        if (row_has[j]) {
          if (src_row < 0) {
            for (int k = 0; k < j; ++k) {
              for (int c = 0; c < 3; ++c) {
                std::memcpy(planes[c] + size_t(by + k) * strides[c] + bx, planes[c] + size_t(by + j) * strides[c] + bx, bw);
              }
            }
          }
          src_row = j;
        } else if (src_row >= 0) {
          for (int c = 0; c < 3; ++c) {
            std::memcpy(planes[c] + size_t(by + j) * strides[c] + bx, planes[c] + size_t(by + src_row) * strides[c] + bx,
                        bw);
          }
        }
      }
    }
  }
}

// libavcodec logs every bitstream error of untrusted input and every
// encoder's statistics to stderr; our errors travel as Status instead. The
// level is process-wide (no other module of ours uses libavcodec).
void QuietLibav() {
  static std::once_flag once;
  std::call_once(once, [] { av_log_set_level(AV_LOG_FATAL); });
}

const char* EncoderName(VideoLibrary lib) {
  switch (lib) {
    case VideoLibrary::kH264: return "libx264";
    case VideoLibrary::kVp9: return "libvpx-vp9";
  }
  return "";
}

const char* DecoderName(VideoLibrary lib) {
  switch (lib) {
    case VideoLibrary::kH264: return "h264";
    case VideoLibrary::kVp9: return "libvpx-vp9";
  }
  return "";
}

struct CodecCtxDeleter {
  void operator()(AVCodecContext* c) const { avcodec_free_context(&c); }
};
struct FrameDeleter {
  void operator()(AVFrame* f) const { av_frame_free(&f); }
};
struct PacketDeleter {
  void operator()(AVPacket* p) const { av_packet_free(&p); }
};
using CodecCtxPtr = std::unique_ptr<AVCodecContext, CodecCtxDeleter>;
using FramePtr = std::unique_ptr<AVFrame, FrameDeleter>;
using PacketPtr = std::unique_ptr<AVPacket, PacketDeleter>;


}  // namespace

const char* VideoLibraryName(VideoLibrary library) {
  switch (library) {
    case VideoLibrary::kH264: return "x264";
    case VideoLibrary::kVp9: return "vpx-vp9";
  }
  return "?";
}

Status VideoEncodeOptions::Check() const {
  if (library != VideoLibrary::kH264 && library != VideoLibrary::kVp9) {
    return InvalidArgument("video.library must be 1 (H.264) or 2 (VP9), got " + Str(uint8_t(library)));
  }
  const int max_crf = library == VideoLibrary::kH264 ? 51 : 63;
  if (crf < -1 || crf > max_crf) {
    return InvalidArgument("video.crf must be -1 or 0.." + std::to_string(max_crf) + ", got " + std::to_string(crf));
  }
  if (keyframe_interval < 1 || keyframe_interval > 1000) {
    return InvalidArgument("video.keyframe_interval must be 1..1000, got " + std::to_string(keyframe_interval));
  }
  if (!preset.empty()) {
    if (library == VideoLibrary::kH264) {
      static constexpr const char* kPresets[] = {"ultrafast", "superfast", "veryfast", "faster", "fast",
                                                 "medium",    "slow",      "slower",   "veryslow"};
      if (std::find(std::begin(kPresets), std::end(kPresets), preset) == std::end(kPresets)) {
        return InvalidArgument("video.preset for x264 must be ultrafast, superfast, veryfast, faster, fast, medium, "
                               "slow, slower or veryslow, got '" + preset + "'");
      }
    } else if (preset.size() != 1 || preset[0] < '5' || preset[0] > '9') {
      return InvalidArgument("video.preset for VP9 is its cpu-used, 5..9, got '" + preset + "'");
    }
  }
  return OkStatus();
}

// ------------------------------------------------------------ encoder

struct VideoEncoder::Impl {
  CodecCtxPtr ctx;
  FramePtr frame;
  PacketPtr packet;
  int width = 0, height = 0;  // the stream's images
  int pic_w = 0, pic_h = 0;   // the open library's pictures (the window's size)
  int seen_w = 0, seen_h = 0; // the largest foreground block rectangle since the last keyframe
  std::vector<uint8_t> block_types;  // this image's 16×16 block types (ClassifyMaskBlocks)
  // 4:2:0: the full-resolution chroma planes before subsampling.
  std::vector<uint8_t> cb, cr;
  std::vector<uint8_t> rle, zmask;
};

VideoEncoder::VideoEncoder(const VideoEncodeOptions& options) : options_(options), impl_(std::make_unique<Impl>()) {}
VideoEncoder::~VideoEncoder() = default;

StatusOr<std::unique_ptr<VideoEncoder>> VideoEncoder::Create(const VideoEncodeOptions& options) {
  HOLO_RETURN_IF_ERROR(options.Check());
  QuietLibav();
  if (!avcodec_find_encoder_by_name(EncoderName(options.library))) {
    return Unavailable(std::string("video: this libavcodec has no ") + EncoderName(options.library) + " encoder");
  }
  return std::unique_ptr<VideoEncoder>(new VideoEncoder(options));
}

namespace {

Status OpenEncoder(const VideoEncodeOptions& o, int w, int h, CodecCtxPtr* out) {
  const AVCodec* codec = avcodec_find_encoder_by_name(EncoderName(o.library));
  if (!codec) return Unavailable(std::string("video: no ") + EncoderName(o.library) + " encoder");
  CodecCtxPtr ctx(avcodec_alloc_context3(codec));
  if (!ctx) return Internal("video: cannot allocate an encoder context");
  ctx->width = w;
  ctx->height = h;
  ctx->time_base = AVRational{1, 30};
  ctx->framerate = AVRational{30, 1};
  ctx->pix_fmt = o.chroma_444 ? AV_PIX_FMT_YUV444P : AV_PIX_FMT_YUV420P;
  ctx->color_range = AVCOL_RANGE_JPEG;
  ctx->colorspace = AVCOL_SPC_BT470BG;
  ctx->gop_size = o.keyframe_interval;
  ctx->keyint_min = o.keyframe_interval;
  ctx->max_b_frames = 0;
  ctx->thread_count = 1;
  ctx->bit_rate = 0;
  AVDictionary* opts = nullptr;
  switch (o.library) {
    case VideoLibrary::kH264:
      av_dict_set(&opts, "preset", o.preset.empty() ? "veryfast" : o.preset.c_str(), 0);
      av_dict_set(&opts, "tune", "zerolatency,psnr", 0);
      av_dict_set(&opts, "crf", std::to_string(o.crf < 0 ? 24 : o.crf).c_str(), 0);
      av_dict_set(&opts, "forced-idr", "1", 0);
      av_dict_set(&opts, "x264-params", "scenecut=0:rc-lookahead=0:sync-lookahead=0:bframes=0", 0);
      break;
    case VideoLibrary::kVp9:
      av_dict_set(&opts, "deadline", "realtime", 0);
      av_dict_set(&opts, "cpu-used", o.preset.empty() ? "8" : o.preset.c_str(), 0);
      av_dict_set(&opts, "lag-in-frames", "0", 0);
      av_dict_set(&opts, "crf", std::to_string(o.crf < 0 ? 32 : o.crf).c_str(), 0);
      av_dict_set(&opts, "row-mt", "0", 0);
      break;
  }
  const int err = avcodec_open2(ctx.get(), codec, &opts);
  av_dict_free(&opts);
  if (err < 0) return Internal(std::string("video: cannot open ") + EncoderName(o.library) + ": " + AvError(err));
  *out = std::move(ctx);
  return OkStatus();
}

}  // namespace

// ------------------------------------------------------------ window
// How the encoder picks the picture's window (PROTOCOL.md §8 leaves it to
// the encoder; the decoder only checks that the mask lies inside).

namespace {

constexpr int kWindowStep = kMaskBlock;  // the window moves in block steps, so its blocks stay the image's blocks

int AlignDown(int v) { return v / kWindowStep * kWindowStep; }
int AlignUp(int v) { return (v + kWindowStep - 1) / kWindowStep * kWindowStep; }

// The 16×16 blocks of the image that hold foreground (from their types,
// ClassifyMaskBlocks), as one rectangle clamped to the image; w = 0 when
// there is no foreground.
VideoWindow ForegroundBlocks(const std::vector<uint8_t>& types, int w, int h) {
  const int bw = (w + kMaskBlock - 1) / kMaskBlock, bh = (h + kMaskBlock - 1) / kMaskBlock;
  int x0 = bw, x1 = -1, y0 = -1, y1 = -1;
  for (int by = 0; by < bh; ++by) {
    const uint8_t* t = types.data() + size_t(by) * bw;
    int a = 0;
    while (a < bw && t[a] == 0) ++a;
    if (a == bw) continue;
    int b = bw - 1;
    while (t[b] == 0) --b;
    x0 = std::min(x0, a);
    x1 = std::max(x1, b);
    if (y0 < 0) y0 = by;
    y1 = by;
  }
  if (y0 < 0) return {};
  VideoWindow r;
  r.x = x0 * kWindowStep;
  r.y = y0 * kWindowStep;
  r.w = std::min((x1 + 1) * kWindowStep, w) - r.x;
  r.h = std::min((y1 + 1) * kWindowStep, h) - r.y;
  return r;
}

// A window size for `need` with room to spare: a quarter of its size more,
// at least two blocks, on each axis (at most the image). Measured on the
// fused sequences (docs/codecs.md): half more left S8-VGA pictures at 86 %
// of the image (no time saved), a quarter at 74 %; on S8-QVGA a quarter
// made 9 keyframes for growth in 150 frames of 8 pods (an arm swung out),
// half 6.
int RoomyLength(int need, int image) { return std::min(image, AlignUp(need + std::max(2 * kWindowStep, need / 4))); }

// The start of a window of length `len` (≥ need_len) on one axis that holds
// [need_pos, need_pos + need_len): centred on it when `centre`, else moved
// from `cur` as little as possible; on the block grid where it can be.
int PlaceAxis(int cur, int len, int need_pos, int need_len, int image, bool centre) {
  int x = cur;
  if (centre) {
    x = AlignDown(need_pos + need_len / 2 - len / 2);
    if (x + len < need_pos + need_len) x = AlignUp(need_pos + need_len - len);
  } else if (need_pos < cur) {
    x = need_pos;
  } else if (need_pos + need_len > cur + len) {
    x = AlignUp(need_pos + need_len - len);
  }
  return std::clamp(x, 0, image - len);
}

}  // namespace

Status VideoEncoder::Encode(const ImageRgb8& image, const ImageGray8& mask, std::vector<uint8_t>* out) {
  const int w = image.width(), h = image.height();
  if (w <= 0 || h <= 0 || w > 8192 || h > 8192 || (w & 1) || (h & 1)) {
    return InvalidArgument("video: image must be even-sized, 2..8192 per side, got " + Str(w) + "x" + Str(h));
  }
  if (!mask.empty() && (mask.width() != w || mask.height() != h)) {
    return InvalidArgument("video: mask " + Str(mask.width()) + "x" + Str(mask.height()) + " != image " + Str(w) + "x" +
                           Str(h));
  }
  Impl& s = *impl_;
  if (s.width != 0 && (w != s.width || h != s.height)) {
    return InvalidArgument("video: the stream's images are " + Str(s.width) + "x" + Str(s.height) + ", got " + Str(w) +
                           "x" + Str(h));
  }
  // The window: kept while the foreground stays inside, moved when it fits
  // elsewhere, chosen anew (size and place) at a keyframe, and resized with
  // a keyframe when the foreground outgrows it.
  if (options_.window || options_.mask_blocks) ClassifyMaskBlocks(mask, w, h, &s.block_types);
  VideoWindow win{0, 0, w, h};
  if (options_.window) {
    const VideoWindow need = ForegroundBlocks(s.block_types, w, h);
    const bool key_due = !s.ctx || keyframe_requested_ || since_keyframe_ >= options_.keyframe_interval;
    win = s.ctx ? window_ : VideoWindow{0, 0, std::min(w, kWindowStep), std::min(h, kWindowStep)};
    if (need.w > 0) {
      const bool fits = need.w <= win.w && need.h <= win.h;
      // A new size is made for the largest foreground since the last
      // keyframe, not just this one: room for the motion of the last interval
      // (an arm that swung out once will likely swing out again).
      const int roomy_w = RoomyLength(std::max(need.w, s.seen_w), w);
      const int roomy_h = RoomyLength(std::max(need.h, s.seen_h), h);
      s.seen_w = key_due ? need.w : std::max(s.seen_w, need.w);
      s.seen_h = key_due ? need.h : std::max(s.seen_h, need.h);
      // At a keyframe the size may change for free: grow to fit, or shrink
      // when a roomy window would be much smaller (less than 60 %).
      const bool resize = !fits || (key_due && int64_t{roomy_w} * roomy_h * 10 < int64_t{win.w} * win.h * 6);
      if (resize && !key_due) {
        // Between keyframes the window only grows: a foreground that grew on
        // one axis keeps the room it had on the other.
        ++window_resizes_;
        win.w = std::max(win.w, roomy_w);
        win.h = std::max(win.h, roomy_h);
      } else if (resize) {
        win.w = roomy_w;
        win.h = roomy_h;
      }
      win.x = PlaceAxis(win.x, win.w, need.x, need.w, w, key_due || resize);
      win.y = PlaceAxis(win.y, win.h, need.y, need.h, h, key_due || resize);
    }
  }
  if (s.ctx && (win.w != s.pic_w || win.h != s.pic_h)) s.ctx.reset();
  if (!s.ctx) {
    HOLO_RETURN_IF_ERROR(OpenEncoder(options_, win.w, win.h, &s.ctx));
    s.width = w;
    s.height = h;
    s.pic_w = win.w;
    s.pic_h = win.h;
    s.frame.reset(av_frame_alloc());
    s.packet.reset(av_packet_alloc());
    if (!s.frame || !s.packet) return Internal("video: cannot allocate a frame");
    s.frame->format = s.ctx->pix_fmt;
    s.frame->width = win.w;
    s.frame->height = win.h;
    s.frame->color_range = AVCOL_RANGE_JPEG;
    if (av_frame_get_buffer(s.frame.get(), 0) < 0) return Internal("video: cannot allocate frame planes");
    since_keyframe_ = 0;
    keyframe_requested_ = true;
  }
  window_ = win;
  AVFrame* f = s.frame.get();
  if (av_frame_make_writable(f) < 0) return Internal("video: cannot make the frame writable");
  if (options_.chroma_444) {
    uint8_t* planes[3] = {f->data[0], f->data[1], f->data[2]};
    const int strides[3] = {f->linesize[0], f->linesize[1], f->linesize[2]};
    ConvertAndFill(image, mask, win, planes, strides);
  } else {
    const int pw = win.w, ph = win.h;
    s.cb.resize(size_t(pw) * ph);
    s.cr.resize(size_t(pw) * ph);
    uint8_t* planes[3] = {f->data[0], s.cb.data(), s.cr.data()};
    const int strides[3] = {f->linesize[0], pw, pw};
    ConvertAndFill(image, mask, win, planes, strides);
    for (int y = 0; y < ph / 2; ++y) {
      const uint8_t* a = s.cb.data() + size_t(2 * y) * pw;
      const uint8_t* b = s.cr.data() + size_t(2 * y) * pw;
      uint8_t* u = f->data[1] + size_t(y) * f->linesize[1];
      uint8_t* v = f->data[2] + size_t(y) * f->linesize[2];
      for (int x = 0; x < pw / 2; ++x) {
        u[x] = static_cast<uint8_t>((a[2 * x] + a[2 * x + 1] + a[pw + 2 * x] + a[pw + 2 * x + 1] + 2) >> 2);
        v[x] = static_cast<uint8_t>((b[2 * x] + b[2 * x + 1] + b[pw + 2 * x] + b[pw + 2 * x + 1] + 2) >> 2);
      }
    }
  }
  const bool force_key = keyframe_requested_ || since_keyframe_ >= options_.keyframe_interval;
  f->pict_type = force_key ? AV_PICTURE_TYPE_I : AV_PICTURE_TYPE_NONE;
  f->pts = frame_number_;
  int err = avcodec_send_frame(s.ctx.get(), f);
  if (err >= 0) err = avcodec_receive_packet(s.ctx.get(), s.packet.get());
  if (err < 0) {
    // Start over: the next image opens a fresh encoder and is a keyframe.
    s.ctx.reset();
    return Internal(std::string("video: ") + EncoderName(options_.library) +
                    (err == AVERROR(EAGAIN) ? " held the frame back (not zero-latency)" : ": " + AvError(err)));
  }
  const bool key = (s.packet->flags & AV_PKT_FLAG_KEY) != 0;
  if (force_key && !key) {
    av_packet_unref(s.packet.get());
    s.ctx.reset();
    return Internal(std::string("video: ") + EncoderName(options_.library) + " ignored a keyframe request");
  }
  if (options_.mask_blocks) {
    HOLO_RETURN_IF_ERROR(EncodeMaskBlocks(mask, w, h, &s.block_types, &s.zmask));
  } else {
    HOLO_RETURN_IF_ERROR(EncodeMask(mask, w, h, &s.rle, &s.zmask));
  }
  ByteWriter wr(out);
  wr.U8(kColorCodecVideo);
  wr.U8(static_cast<uint8_t>((key ? kVideoFlagKeyframe : 0) | (options_.chroma_444 ? kVideoFlagChroma444 : 0) |
                             (options_.mask_blocks ? kVideoFlagMaskBlocks : 0) |
                             (options_.window ? kVideoFlagWindow : 0)));
  wr.U16(static_cast<uint16_t>(w));
  wr.U16(static_cast<uint16_t>(h));
  wr.U8(static_cast<uint8_t>(options_.library));
  wr.U32(frame_number_);
  if (options_.window) {
    wr.U16(static_cast<uint16_t>(win.x));
    wr.U16(static_cast<uint16_t>(win.y));
    wr.U16(static_cast<uint16_t>(win.w));
    wr.U16(static_cast<uint16_t>(win.h));
  }
  wr.Blob32(s.zmask);
  wr.Blob32(std::span<const uint8_t>(s.packet->data, static_cast<size_t>(s.packet->size)));
  av_packet_unref(s.packet.get());
  ++frame_number_;
  if (key) {
    ++keyframes_;
    since_keyframe_ = 1;
    keyframe_requested_ = false;
  } else {
    ++since_keyframe_;
  }
  return OkStatus();
}

// ------------------------------------------------------------ decoder

StatusOr<VideoBlobInfo> ParseVideoBlob(std::span<const uint8_t> blob, const Limits& limits) {
  ByteReader r(blob);
  VideoBlobInfo info;
  uint8_t codec = 0, lib = 0;
  uint16_t w = 0, h = 0;
  HOLO_RETURN_IF_ERROR(r.U8("v1.codec", &codec));
  if (codec != kColorCodecVideo) return DataLoss("v1.codec: " + Str(codec) + " is not the video codec (4)");
  HOLO_RETURN_IF_ERROR(r.U8("v1.flags", &info.flags));
  if (info.flags & ~(kVideoFlagKeyframe | kVideoFlagChroma444 | kVideoFlagMaskBlocks | kVideoFlagWindow)) {
    return DataLoss("v1.flags: unknown bits in " + Str(info.flags));
  }
  HOLO_RETURN_IF_ERROR(r.U16("v1.width", &w));
  HOLO_RETURN_IF_ERROR(r.U16("v1.height", &h));
  if (w == 0 || h == 0 || (w & 1) || (h & 1) || w > limits.max_image_dim || h > limits.max_image_dim ||
      uint64_t{w} * h > limits.max_image_pixels) {
    return DataLoss("v1.size: " + Str(w) + "x" + Str(h) + " is not even or exceeds the limits");
  }
  info.width = w;
  info.height = h;
  HOLO_RETURN_IF_ERROR(r.U8("v1.library", &lib));
  if (lib == 3) return UnsupportedVersion("v1.library: 3 (AV1) is reserved, not implemented");
  if (lib < 1 || lib > 3) return UnsupportedVersion("v1.library: unknown video library " + Str(lib));
  info.library = static_cast<VideoLibrary>(lib);
  HOLO_RETURN_IF_ERROR(r.U32("v1.frame_number", &info.frame_number));
  info.window = VideoWindow{0, 0, w, h};
  if (info.flags & kVideoFlagWindow) {
    uint16_t x = 0, y = 0, ww = 0, wh = 0;
    HOLO_RETURN_IF_ERROR(r.U16("v1.window_x", &x));
    HOLO_RETURN_IF_ERROR(r.U16("v1.window_y", &y));
    HOLO_RETURN_IF_ERROR(r.U16("v1.window_width", &ww));
    HOLO_RETURN_IF_ERROR(r.U16("v1.window_height", &wh));
    if (ww == 0 || wh == 0 || (ww & 1) || (wh & 1) || x + ww > w || y + wh > h) {
      return DataLoss("v1.window: " + Str(ww) + "x" + Str(wh) + " at " + Str(x) + "," + Str(y) +
                      " is not even-sized or leaves the " + Str(w) + "x" + Str(h) + " image");
    }
    info.window = VideoWindow{x, y, ww, wh};
  }
  std::span<const uint8_t> zmask, video;
  info.mask_offset = r.position() + 4;
  HOLO_RETURN_IF_ERROR(r.Blob32("v1.mask", r.remaining(), &zmask));
  info.video_offset = r.position() + 4;
  HOLO_RETURN_IF_ERROR(r.Blob32("v1.video", r.remaining(), &video));
  HOLO_RETURN_IF_ERROR(r.ExpectEnd("v1 blob"));
  if (video.empty()) return DataLoss("v1.video: empty picture");
  info.mask_bytes = zmask.size();
  info.video_bytes = video.size();
  return info;
}

struct VideoDecoder::Impl {
  CodecCtxPtr ctx;
  FramePtr frame;
  FramePtr extra;  // receives a second picture of a blob, if any (refused)
  PacketPtr packet;
  VideoLibrary library = VideoLibrary::kH264;
  uint8_t chroma_flag = 0;
  uint32_t width = 0, height = 0;  // the stream's images
  uint32_t pic_w = 0, pic_h = 0;   // its pictures (the window's size)
  uint32_t last_frame = 0;
  VideoWindow drawn;  // the window of the picture in image_ (the only part of it that may be non-zero)
  std::vector<uint8_t> rle;
  std::vector<uint8_t> padded;
};

VideoDecoder::VideoDecoder() : impl_(std::make_unique<Impl>()) { QuietLibav(); }
VideoDecoder::~VideoDecoder() = default;

namespace {

Status OpenDecoder(VideoLibrary lib, uint32_t w, uint32_t h, CodecCtxPtr* out) {
  const AVCodec* codec = avcodec_find_decoder_by_name(DecoderName(lib));
  if (!codec) return Unavailable(std::string("video: this libavcodec has no ") + DecoderName(lib) + " decoder");
  CodecCtxPtr ctx(avcodec_alloc_context3(codec));
  if (!ctx) return Internal("video: cannot allocate a decoder context");
  ctx->thread_count = 1;
  ctx->flags |= AV_CODEC_FLAG_LOW_DELAY;
  ctx->err_recognition = AV_EF_EXPLODE;
  // The library may not allocate much more than the header's picture (its
  // buffers are padded and aligned beyond the picture, hence the margin; a
  // picture of another size is refused after decoding).
  ctx->max_pixels = (int64_t{w} + 128) * (int64_t{h} + 128);
  ctx->width = static_cast<int>(w);
  ctx->height = static_cast<int>(h);
  const int err = avcodec_open2(ctx.get(), codec, nullptr);
  if (err < 0) return Internal(std::string("video: cannot open ") + DecoderName(lib) + ": " + AvError(err));
  *out = std::move(ctx);
  return OkStatus();
}

// Every foreground pixel of the mask must lie in the window (the picture
// holds no colour for any other).
Status CheckMaskInside(const ImageGray8& mask, const VideoWindow& win) {
  const auto outside = [](const uint8_t* a, const uint8_t* b) { return std::find_if(a, b, [](uint8_t v) { return v; }) != b; };
  for (int y = 0; y < mask.height(); ++y) {
    const uint8_t* m = mask.row(y);
    const bool in_rows = y >= win.y && y < win.y + win.h;
    if (in_rows ? outside(m, m + win.x) || outside(m + win.x + win.w, m + mask.width())
                : outside(m, m + mask.width())) {
      return DataLoss("v1.mask: foreground in row " + Str(y) + " outside the window " + Str(win.w) + "x" +
                      Str(win.h) + " at " + Str(win.x) + "," + Str(win.y));
    }
  }
  return OkStatus();
}

}  // namespace

Status VideoDecoder::Decode(std::span<const uint8_t> blob, const Limits& limits) {
  Impl& s = *impl_;
  const bool was_synced = synced_;
  synced_ = false;  // until this blob decodes
  auto info_or = ParseVideoBlob(blob, limits);
  if (!info_or.ok()) return info_or.status();
  const VideoBlobInfo& info = *info_or;
  const VideoWindow& win = info.window;
  const uint8_t chroma = info.flags & kVideoFlagChroma444;
  if (!info.keyframe()) {
    if (!was_synced) return Unavailable("v1: delta frame " + Str(info.frame_number) + ": waiting for a keyframe");
    if (info.frame_number != s.last_frame + 1) {
      return Unavailable("v1: frame " + Str(info.frame_number) + " after " + Str(s.last_frame) +
                         ": frames missing, waiting for a keyframe");
    }
    if (info.width != s.width || info.height != s.height || uint32_t(win.w) != s.pic_w ||
        uint32_t(win.h) != s.pic_h || info.library != s.library || chroma != s.chroma_flag) {
      return Unavailable("v1: delta frame " + Str(info.frame_number) +
                         " changes the stream's size, library or chroma: waiting for a keyframe");
    }
  }
  // Both blobs were bounds-checked by ParseVideoBlob.
  const std::span<const uint8_t> zmask = blob.subspan(info.mask_offset, info.mask_bytes);
  const std::span<const uint8_t> video = blob.subspan(info.video_offset, info.video_bytes);
  if (info.flags & kVideoFlagMaskBlocks) {
    HOLO_RETURN_IF_ERROR(
        DecodeMaskBlocks(zmask, static_cast<int>(info.width), static_cast<int>(info.height), &s.rle, &mask_));
  } else {
    HOLO_RETURN_IF_ERROR(DecodeMask(zmask, static_cast<int>(info.width), static_cast<int>(info.height), &s.rle, &mask_));
  }
  HOLO_RETURN_IF_ERROR(CheckMaskInside(mask_, win));

  if (info.keyframe()) {
    if (!s.ctx || info.library != s.library || uint32_t(win.w) != s.pic_w || uint32_t(win.h) != s.pic_h ||
        chroma != s.chroma_flag) {
      s.ctx.reset();
      HOLO_RETURN_IF_ERROR(OpenDecoder(info.library, uint32_t(win.w), uint32_t(win.h), &s.ctx));
      s.library = info.library;
      s.pic_w = uint32_t(win.w);
      s.pic_h = uint32_t(win.h);
      s.chroma_flag = chroma;
    } else {
      avcodec_flush_buffers(s.ctx.get());
    }
    s.width = info.width;
    s.height = info.height;
  }
  if (!s.frame) s.frame.reset(av_frame_alloc());
  if (!s.extra) s.extra.reset(av_frame_alloc());
  if (!s.packet) s.packet.reset(av_packet_alloc());
  if (!s.frame || !s.extra || !s.packet) return Internal("video: cannot allocate a frame");
  // libavcodec reads up to AV_INPUT_BUFFER_PADDING_SIZE bytes past the data.
  s.padded.assign(video.size() + AV_INPUT_BUFFER_PADDING_SIZE, 0);
  std::memcpy(s.padded.data(), video.data(), video.size());
  s.packet->data = s.padded.data();
  s.packet->size = static_cast<int>(video.size());
  int err = avcodec_send_packet(s.ctx.get(), s.packet.get());
  s.packet->data = nullptr;
  s.packet->size = 0;
  if (err < 0) {
    s.ctx.reset();
    return DataLoss("v1.video: the " + std::string(DecoderName(info.library)) + " decoder refused the picture: " +
                    AvError(err));
  }
  err = avcodec_receive_frame(s.ctx.get(), s.frame.get());
  if (err < 0) {
    s.ctx.reset();
    return DataLoss("v1.video: no picture came out of the blob" + (err == AVERROR(EAGAIN) ? "" : ": " + AvError(err)));
  }
  AVFrame* f = s.frame.get();
  const bool is444 = f->format == AV_PIX_FMT_YUV444P || f->format == AV_PIX_FMT_YUVJ444P;
  const bool is420 = f->format == AV_PIX_FMT_YUV420P || f->format == AV_PIX_FMT_YUVJ420P;
  Status bad;
  if (f->width != win.w || f->height != win.h) {
    bad = DataLoss("v1.video: picture is " + Str(f->width) + "x" + Str(f->height) + ", the header says " +
                   Str(win.w) + "x" + Str(win.h));
  } else if (!(chroma ? is444 : is420)) {
    const char* name = av_get_pix_fmt_name(static_cast<AVPixelFormat>(f->format));
    bad = DataLoss(std::string("v1.video: picture format ") + (name ? name : "?") + " does not match the header");
  } else if (f->decode_error_flags != 0 || (f->flags & AV_FRAME_FLAG_CORRUPT)) {
    bad = DataLoss("v1.video: the picture has decode errors");
  }
  // One blob is one picture: a second one would come out with the next blob.
  if (bad.ok() && avcodec_receive_frame(s.ctx.get(), s.extra.get()) != AVERROR(EAGAIN)) {
    av_frame_unref(s.extra.get());
    bad = DataLoss("v1.video: the blob holds more than one picture");
  }
  if (!bad.ok()) {
    av_frame_unref(f);
    s.ctx.reset();
    return bad;
  }
  // The image keeps its background at 0 without clearing it whole: only the
  // last picture's window can hold colour, so what of it lies outside this
  // window is cleared, and this window is written in full (foreground runs
  // converted, background runs cleared).
  const int iw = static_cast<int>(info.width), ih = static_cast<int>(info.height);
  if (image_.width() != iw || image_.height() != ih) {
    image_.Resize(iw, ih, 0);
  } else {
    const VideoWindow& old = s.drawn;
    for (int y = old.y; y < old.y + old.h; ++y) {
      uint8_t* row = image_.row(y);
      if (y < win.y || y >= win.y + win.h) {
        std::memset(row + size_t(old.x) * 3, 0, size_t(old.w) * 3);
        continue;
      }
      const int left_end = std::min(old.x + old.w, win.x), right_start = std::max(old.x, win.x + win.w);
      if (left_end > old.x) std::memset(row + size_t(old.x) * 3, 0, size_t(left_end - old.x) * 3);
      if (old.x + old.w > right_start)
        std::memset(row + size_t(right_start) * 3, 0, size_t(old.x + old.w - right_start) * 3);
    }
  }
  const int shift = chroma ? 0 : 1;
  for (int y = 0; y < win.h; ++y) {
    const uint8_t* m = mask_.row(win.y + y) + win.x;
    const uint8_t* py = f->data[0] + size_t(y) * f->linesize[0];
    const uint8_t* pu = f->data[1] + size_t(y >> shift) * f->linesize[1];
    const uint8_t* pv = f->data[2] + size_t(y >> shift) * f->linesize[2];
    uint8_t* dst = image_.row(win.y + y) + size_t(win.x) * 3;
    for (int x = 0; x < win.w;) {
      const int a = x;
      while (x < win.w && !m[x]) ++x;
      std::memset(dst + size_t(a) * 3, 0, size_t(x - a) * 3);
      const int b = x;
      while (x < win.w && m[x]) ++x;
      YccToRgbRow(py, pu, pv, shift, b, x, dst);
    }
  }
  s.drawn = win;
  av_frame_unref(f);
  s.last_frame = info.frame_number;
  synced_ = true;
  return OkStatus();
}

}  // namespace holo::protocol
