#pragma once

#include <algorithm>
#include <bit>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "common/status.h"

namespace holo::protocol::rans {

// The static rANS token coder shared by the geometry codec G1 (PROTOCOL.md
// §7 "Coded streams") and the depth codec D2 (§8.2). Internal to
// holo_protocol: not part of the public API.
//
// Static rANS (byte-wise renormalisation, 32-bit state, 12-bit probabilities)
// over tokens 0..63 with one frequency table per context. Integer values are
// tokenised like an Elias-gamma code with the top two bits in the token:
// values < 16 are their own token, larger values carry their lower bits as raw
// bits in a separate bit stream. See PROTOCOL.md §7 "Coded streams".

constexpr uint32_t kTokens = 64;
constexpr uint32_t kProbBits = 12;
constexpr uint32_t kProbScale = 1u << kProbBits;
// No symbol may be more probable than this: every coded symbol then costs at
// least -log2(4032/4096) ≈ 0.0227 bits, which bounds what a number of bytes can
// decode to (kMaxSymbolsPerByte) before anything is allocated.
constexpr uint32_t kMaxFreq = kProbScale - 64;
constexpr uint64_t kMaxSymbolsPerByte = 353;  // 8 / 0.0227, rounded up
constexpr uint32_t kRansLow = 1u << 23;
__extension__ typedef unsigned __int128 U128;  // GCC and Clang

inline void Tokenize(uint32_t z, uint32_t* tok, uint32_t* nbits) {
  if (z < 16) {
    *tok = z;
    *nbits = 0;
    return;
  }
  const uint32_t n = static_cast<uint32_t>(std::bit_width(z));  // 5..32
  *tok = 16 + 2 * (n - 5) + ((z >> (n - 2)) & 1u);
  *nbits = n - 2;
}

inline uint32_t ZigZag(int32_t v) { return (static_cast<uint32_t>(v) << 1) ^ static_cast<uint32_t>(v >> 31); }
inline int32_t UnZigZag(uint32_t z) { return static_cast<int32_t>(z >> 1) ^ -static_cast<int32_t>(z & 1u); }

// Collects tokens per context, then writes tables, the rANS bytes and the raw bits.
class TokenWriter {
 public:
  // `storage` (borrowed until Finish; may be null) keeps the symbol buffer's
  // memory between frames.
  explicit TokenWriter(uint32_t contexts, size_t expected_symbols = 0, std::vector<uint16_t>* storage = nullptr)
      : contexts_(contexts), counts_(size_t{contexts} * kTokens, 0), syms_(storage ? *storage : own_) {
    syms_.clear();
    syms_.reserve(expected_symbols);
  }

  void Put(uint32_t ctx, uint32_t tok) {
    const auto s = static_cast<uint16_t>(ctx * kTokens + tok);
    syms_.push_back(s);
    ++counts_[s];
  }
  // A non-negative value (at most 2^28 - 1).
  void PutValue(uint32_t ctx, uint32_t z) {
    uint32_t tok, nbits;
    Tokenize(z, &tok, &nbits);
    Put(ctx, tok);
    if (nbits) PutBits(z & ((1u << nbits) - 1u), nbits);
  }
  // The same as PutValue for z < 2^16, without a data-dependent branch (the
  // depth codec's residuals: whether one is < 16 is a coin toss).
  void PutValue16(uint32_t ctx, uint32_t z) {
    const uint32_t n = std::max<uint32_t>(static_cast<uint32_t>(std::bit_width(z)), 5);
    const bool small = z < 16;
    const uint32_t tok = small ? z : 16 + 2 * (n - 5) + ((z >> (n - 2)) & 1u);
    const uint32_t nbits = small ? 0 : n - 2;
    Put(ctx, tok);
    PutBits(z & ((1u << nbits) - 1u), nbits);
  }
  void PutBits(uint32_t v, uint32_t n) {  // n ≤ 26
    acc_ |= uint64_t{v} << nacc_;
    nacc_ += n;
    while (nacc_ >= 8) {
      bits_.push_back(static_cast<uint8_t>(acc_));
      acc_ >>= 8;
      nacc_ -= 8;
    }
  }

  // Layout: per context `u8 n` and n varint frequencies; `u32` length and the
  // rANS bytes; the raw bits to the end.
  void Finish(std::vector<uint8_t>* out) {
    if (nacc_) bits_.push_back(static_cast<uint8_t>(acc_));
    std::vector<uint16_t> freq(counts_.size(), 0), start(counts_.size(), 0);
    for (uint32_t c = 0; c < contexts_; ++c) {
      uint32_t* cnt = &counts_[size_t{c} * kTokens];
      uint16_t* f = &freq[size_t{c} * kTokens];
      Normalize(cnt, f);
      uint32_t n = 0, cum = 0;
      for (uint32_t t = 0; t < kTokens; ++t) {
        if (f[t]) n = t + 1;
        start[size_t{c} * kTokens + t] = static_cast<uint16_t>(cum);
        cum += f[t];
      }
      out->push_back(static_cast<uint8_t>(n));
      for (uint32_t t = 0; t < n; ++t) {
        if (f[t] < 128) {
          out->push_back(static_cast<uint8_t>(f[t]));
        } else {
          out->push_back(static_cast<uint8_t>(0x80 | (f[t] & 0x7F)));
          out->push_back(static_cast<uint8_t>(f[t] >> 7));
        }
      }
    }
    // rANS runs backwards: fill a buffer from its end.
    // x / f by multiplication: x < 2^31 after renormalisation and f ≤ 2^12, so
    // m = ceil(2^44 / f) gives floor(x·m / 2^44) = floor(x / f) exactly
    // (m·f − 2^44 < f ≤ 2^(44−31); Granlund & Montgomery 1994).
    std::vector<uint64_t> recip(freq.size(), 0);
    for (size_t i = 0; i < freq.size(); ++i)
      if (freq[i]) recip[i] = ((uint64_t{1} << 44) + freq[i] - 1) / freq[i];
    thread_local std::vector<uint8_t> rans;  // kept between frames
    rans.resize(syms_.size() * 4 + 16);
    uint8_t* p = rans.data() + rans.size();
    // Two interleaved states (symbol i uses state i mod 2) so that the
    // decoder's two dependency chains overlap.
    uint32_t xs[2] = {kRansLow, kRansLow};
    for (size_t i = syms_.size(); i-- > 0;) {
      uint32_t& x = xs[i & 1];
      const uint16_t s = syms_[i];
      const uint32_t fr = freq[s];
      const uint32_t x_max = ((kRansLow >> kProbBits) << 8) * fr;
      // At most two bytes go out (x < 2^31, x_max ≥ 2^19); branch-free, as
      // the condition is a coin toss for a symbol of a few bits.
      for (int k = 0; k < 2; ++k) {
        const bool out = x >= x_max;
        p[-1] = static_cast<uint8_t>(x);
        p -= out;
        x = out ? x >> 8 : x;
      }
      const auto q = static_cast<uint32_t>((static_cast<U128>(x) * recip[s]) >> 44);
      x = (q << kProbBits) + (x - q * fr) + start[s];
    }
    for (int j = 1; j >= 0; --j) {
      p -= 4;
      for (int i = 0; i < 4; ++i) p[i] = static_cast<uint8_t>(xs[j] >> (8 * i));
    }
    const auto n = static_cast<uint32_t>(rans.data() + rans.size() - p);
    for (int i = 0; i < 4; ++i) out->push_back(static_cast<uint8_t>(n >> (8 * i)));
    out->insert(out->end(), p, p + n);
    out->insert(out->end(), bits_.begin(), bits_.end());
  }

 private:
  // Scales counts to frequencies summing to kProbScale, every used token ≥ 1,
  // none above kMaxFreq. An unused context gets no table (n = 0).
  static void Normalize(const uint32_t* cnt, uint16_t* f) {
    uint64_t total = 0;
    for (uint32_t t = 0; t < kTokens; ++t) total += cnt[t];
    if (total == 0) return;
    uint32_t sum = 0, top = 0;
    for (uint32_t t = 0; t < kTokens; ++t) {
      if (!cnt[t]) continue;
      f[t] = static_cast<uint16_t>(std::max<uint64_t>(1, (uint64_t{cnt[t]} * kProbScale + total / 2) / total));
      sum += f[t];
      if (f[t] > f[top] || !cnt[top]) top = t;
    }
    while (sum > kProbScale) {  // rounding up of rare tokens overshot: take from the largest
      uint32_t m = 0;
      for (uint32_t t = 1; t < kTokens; ++t)
        if (f[t] > f[m]) m = t;
      const uint32_t d = std::min<uint32_t>(sum - kProbScale, f[m] - 1u);
      f[m] = static_cast<uint16_t>(f[m] - d);
      sum -= d;
    }
    if (sum < kProbScale) {
      f[top] = static_cast<uint16_t>(f[top] + kProbScale - sum);
    }
    uint32_t m = 0;
    for (uint32_t t = 1; t < kTokens; ++t)
      if (f[t] > f[m]) m = t;
    if (f[m] > kMaxFreq) {  // give the excess to another token (used or not)
      uint32_t other = m == 0 ? 1 : 0;
      for (uint32_t t = 0; t < kTokens; ++t)
        if (t != m && f[t] > f[other]) other = t;
      f[other] = static_cast<uint16_t>(f[other] + f[m] - kMaxFreq);
      f[m] = static_cast<uint16_t>(kMaxFreq);
    }
  }

  uint32_t contexts_;
  std::vector<uint32_t> counts_;
  std::vector<uint16_t> own_;
  std::vector<uint16_t>& syms_;
  std::vector<uint8_t> bits_;
  uint64_t acc_ = 0;
  uint32_t nacc_ = 0;
};

// Decodes what TokenWriter wrote. Safe on untrusted input: tables are
// validated, every byte read is bounds-checked; errors are sticky (ok() turns
// false and the getters return 0) so hot loops test once at the end.
class TokenReader {
 public:
  Status Init(std::span<const uint8_t> data, uint32_t contexts, const std::string& field) {
    field_ = field;
    // A reader may be reused: every table is marked unused and a used one
    // overwrites all it is read at (sym[] entirely, freq and start below n),
    // so no table needs clearing (192 of them would be 0.8 MB).
    tables_.resize(contexts);
    for (Table& tb : tables_) tb.used = false;
    rpos_ = bpos_ = 0;
    acc_ = 0;
    nacc_ = 0;
    ok_ = true;
    size_t pos = 0;
    auto byte = [&](uint8_t* b) {
      if (pos >= data.size()) return false;
      *b = data[pos++];
      return true;
    };
    for (uint32_t c = 0; c < contexts; ++c) {
      Table& tb = tables_[c];
      uint8_t n = 0;
      if (!byte(&n) || n > kTokens) return DataLoss(field + ": bad frequency table " + std::to_string(c));
      if (n == 0) continue;
      uint32_t cum = 0;
      for (uint32_t t = 0; t < n; ++t) {
        uint8_t lo = 0, hi = 0;
        if (!byte(&lo)) return DataLoss(field + ": truncated frequency table");
        uint32_t fr = lo;
        if (lo & 0x80) {
          if (!byte(&hi)) return DataLoss(field + ": truncated frequency table");
          fr = (lo & 0x7Fu) | (uint32_t{hi} << 7);
        }
        if (fr > kMaxFreq || cum + fr > kProbScale) return DataLoss(field + ": frequencies exceed the scale");
        tb.freq[t] = static_cast<uint16_t>(fr);
        tb.start[t] = static_cast<uint16_t>(cum);
        for (uint32_t k = cum; k < cum + fr; ++k) tb.sym[k] = static_cast<uint8_t>(t);
        cum += fr;
      }
      if (cum != kProbScale) return DataLoss(field + ": frequencies do not sum to 4096");
      tb.used = true;
    }
    if (data.size() - pos < 4) return DataLoss(field + ": missing rANS length");
    uint32_t n = 0;
    for (int i = 0; i < 4; ++i) n |= uint32_t{data[pos + i]} << (8 * i);
    pos += 4;
    if (n > data.size() - pos) return DataLoss(field + ": rANS length out of range");
    rans_.assign(data.begin() + static_cast<std::ptrdiff_t>(pos), data.begin() + static_cast<std::ptrdiff_t>(pos + n));
    rans_end_ = n;
    rans_.push_back(0);
    rans_.push_back(0);
    bits_ = data.subspan(pos + n);
    if (n < 8) return DataLoss(field + ": rANS length out of range");
    x0_ = x1_ = 0;
    for (int i = 0; i < 4; ++i) {
      x0_ |= uint32_t{rans_[i]} << (8 * i);
      x1_ |= uint32_t{rans_[4 + i]} << (8 * i);
    }
    if (x0_ < kRansLow || x1_ < kRansLow) return DataLoss(field + ": bad rANS state");
    rpos_ = 8;
    return OkStatus();
  }
  // Symbols the rANS bytes can hold at most (each costs ≥ 0.0227 bits).
  uint64_t MaxSymbols() const { return (uint64_t{rans_end_} + 1) * kMaxSymbolsPerByte; }

  uint32_t Get(uint32_t ctx) {
    const Table& tb = tables_[ctx];
    if (!tb.used) {
      ok_ = false;
      return 0;
    }
    // x0_ is the state of this symbol, x1_ that of the next: swap after use
    // (two named members rather than an indexed pair, so they stay in registers).
    uint32_t x = x0_;
    const uint32_t slot = x & (kProbScale - 1);
    const uint32_t s = tb.sym[slot];
    x = tb.freq[s] * (x >> kProbBits) + slot - tb.start[s];
    // x ≥ 2^11 here (x ≥ 2^23 before, freq ≥ 1), so at most two bytes come
    // in; branch-free, reading from a copy with two zero bytes of padding.
    for (int k = 0; k < 2; ++k) {
      const bool in = x < kRansLow;
      const uint32_t shifted = (x << 8) | rans_[rpos_];
      x = in ? shifted : x;
      rpos_ += in;
    }
    x0_ = x1_;
    x1_ = x;
    if (rpos_ > rans_end_) {  // read into the padding: the stream was too short
      ok_ = false;
      rpos_ = rans_end_;
    }
    return s;
  }
  uint32_t GetBits(uint32_t n) {  // n ≤ 26
    while (nacc_ < n) {
      if (bpos_ >= bits_.size()) {
        ok_ = false;
        return 0;
      }
      acc_ |= uint64_t{bits_[bpos_++]} << nacc_;
      nacc_ += 8;
    }
    const auto v = static_cast<uint32_t>(acc_ & ((uint64_t{1} << n) - 1));
    acc_ >>= n;
    nacc_ -= n;
    return v;
  }
  // The value of a token below 40 (its raw bits read), without a
  // data-dependent branch; GetValue's result for values < 2^16.
  uint32_t ValueOfToken16(uint32_t tok) {
    const bool small = tok < 16;
    const uint32_t nb = small ? 0 : (tok - 16) / 2 + 3;  // raw bits: bit length − 2
    const uint32_t bits = GetBits(nb);
    const uint32_t big = (1u << (nb + 1)) | ((tok & 1u) << nb) | bits;
    return small ? tok : big;
  }
  uint32_t GetValue(uint32_t ctx) {
    const uint32_t tok = Get(ctx);
    if (tok < 16) return tok;
    const uint32_t n = (tok - 16) / 2 + 5;
    return (1u << (n - 1)) | ((tok & 1u) << (n - 2)) | GetBits(n - 2);
  }
  bool ok() const { return ok_; }
  // OK if every symbol decoded, the rANS state returned to its initial value
  // and no bytes are left over.
  Status Finish() const {
    if (!ok_) return DataLoss(field_ + ": coded data is truncated or corrupt");
    if (x0_ != kRansLow || x1_ != kRansLow || rpos_ != rans_end_) {
      return DataLoss(field_ + ": rANS data does not end cleanly");
    }
    if (bits_.size() - bpos_ > 0) return DataLoss(field_ + ": raw bits left over");
    return OkStatus();
  }

 private:
  struct Table {
    bool used = false;
    uint16_t freq[kTokens] = {};
    uint16_t start[kTokens] = {};
    uint8_t sym[kProbScale] = {};
  };
  std::string field_;
  std::vector<Table> tables_;
  std::vector<uint8_t> rans_;  // the rANS bytes and two zero bytes
  size_t rans_end_ = 0;        // the number of real rANS bytes
  std::span<const uint8_t> bits_;
  size_t rpos_ = 0, bpos_ = 0;
  uint32_t x0_ = 0, x1_ = 0;  // the states of the next two symbols
  uint64_t acc_ = 0;
  uint32_t nacc_ = 0;
  bool ok_ = true;
};

}  // namespace holo::protocol::rans
