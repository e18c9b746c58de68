#include "protocol/geometry_codec.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>

#include <lz4.h>

#include "protocol/byte_io.h"
#include "protocol/rans_coder.h"
#include "protocol/surface_codec.h"

namespace holo::protocol {
namespace {

constexpr uint8_t kHasNormals = 1u << 0;
constexpr uint8_t kHasColors = 1u << 1;
constexpr uint8_t kRecomputeNormals = 1u << 2;
constexpr uint8_t kColorsByMean = 1u << 3;  // G1: colours predicted by the mean, not the parallelogram
constexpr size_t kPrefixBytes = 12;

void WritePrefix(ByteWriter& w, GeometryCodec codec, uint8_t flags, size_t nv, size_t nt) {
  w.U8(static_cast<uint8_t>(codec));
  w.U8(flags);
  w.U16(0);
  w.U32(static_cast<uint32_t>(nv));
  w.U32(static_cast<uint32_t>(nt));
}

// Welds vertices with bit-identical positions (marching cubes emits one copy
// per cell). `weld[i]` is the unique vertex of input vertex i; `unique` lists
// the first input vertex of every unique vertex.
void WeldExactPositions(const Mesh& mesh, std::vector<uint32_t>* weld, std::vector<uint32_t>* unique) {
  const size_t n = mesh.num_vertices();
  size_t cap = 16;
  while (cap < n * 2) cap <<= 1;
  thread_local std::vector<uint32_t> table;  // kept between frames (no fresh pages each time)
  table.assign(cap, UINT32_MAX);
  weld->resize(n);
  unique->clear();
  unique->reserve(n);
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector3f& p = mesh.positions[i];
    uint64_t h = std::bit_cast<uint32_t>(p.x());
    h = h * 0x9E3779B97F4A7C15ull ^ std::bit_cast<uint32_t>(p.y());
    h = h * 0x9E3779B97F4A7C15ull ^ std::bit_cast<uint32_t>(p.z());
    h *= 0xBF58476D1CE4E5B9ull;
    size_t slot = static_cast<size_t>(h >> 20) & (cap - 1);
    while (true) {
      const uint32_t u = table[slot];
      if (u == UINT32_MAX) {
        table[slot] = static_cast<uint32_t>(unique->size());
        (*weld)[i] = static_cast<uint32_t>(unique->size());
        unique->push_back(static_cast<uint32_t>(i));
        break;
      }
      const Eigen::Vector3f& q = mesh.positions[(*unique)[u]];
      if (std::memcmp(q.data(), p.data(), sizeof(float) * 3) == 0) {
        (*weld)[i] = u;
        break;
      }
      slot = (slot + 1) & (cap - 1);
    }
  }
}

Status CheckEncodable(const Mesh& mesh) {
  HOLO_RETURN_IF_ERROR(CheckMesh(mesh));
  const Limits limits;
  if (mesh.num_vertices() > limits.max_vertices) {
    return InvalidArgument("mesh has " + Str(mesh.num_vertices()) + " vertices, protocol limit " +
                           Str(limits.max_vertices));
  }
  if (mesh.num_triangles() > limits.max_triangles) {
    return InvalidArgument("mesh has " + Str(mesh.num_triangles()) + " triangles, protocol limit " +
                           Str(limits.max_triangles));
  }
  return OkStatus();
}

// ------------------------------------------------------------------ G0

Status EncodeG0(const Mesh& mesh, const GeometryEncodeOptions& o, std::vector<uint8_t>* out,
                std::vector<uint32_t>* vertex_map) {
  std::vector<uint32_t> weld, unique;
  WeldExactPositions(mesh, &weld, &unique);
  const bool normals = o.normals != NormalMode::kNone && !mesh.normals.empty();
  const bool colors = o.colors && !mesh.colors.empty();
  const size_t n = unique.size();
  ByteWriter w(out);
  out->reserve(out->size() + kPrefixBytes + n * (6 + 6 + 3) + mesh.num_triangles() * 12 / 2);
  WritePrefix(w, GeometryCodec::kG0, static_cast<uint8_t>((normals ? kHasNormals : 0) | (colors ? kHasColors : 0)), n,
              mesh.num_triangles());
  for (uint32_t i : unique)
    for (int c = 0; c < 3; ++c) w.U16(FloatToHalf(mesh.positions[i][c]));
  if (normals) {
    for (uint32_t i : unique)
      for (int c = 0; c < 3; ++c) w.U16(FloatToHalf(mesh.normals[i][c]));
  }
  if (colors) {
    for (uint32_t i : unique) w.Bytes(mesh.colors[i]);
  }
  std::vector<uint32_t> idx(mesh.num_triangles() * 3);
  for (size_t t = 0; t < mesh.num_triangles(); ++t)
    for (int c = 0; c < 3; ++c) idx[t * 3 + c] = weld[mesh.triangles[t][c]];
  const int src_bytes = static_cast<int>(idx.size() * 4);
  const size_t size_at = w.ReserveU32();
  if (src_bytes == 0) {  // no triangles: no index bytes at all
    if (vertex_map) *vertex_map = std::move(weld);
    return OkStatus();
  }
  const size_t start = out->size();
  out->resize(start + static_cast<size_t>(LZ4_compressBound(src_bytes)));
  const int lz = LZ4_compress_default(reinterpret_cast<const char*>(idx.data()),
                                      reinterpret_cast<char*>(out->data() + start), src_bytes,
                                      static_cast<int>(out->size() - start));
  if (lz <= 0) return Internal("LZ4 compression of the indices failed");
  out->resize(start + static_cast<size_t>(lz));
  w.PatchU32(size_at, static_cast<uint32_t>(lz));
  if (vertex_map) *vertex_map = std::move(weld);
  return OkStatus();
}

Status DecodeG0(ByteReader& r, uint8_t flags, uint32_t nv, uint32_t nt, Mesh* mesh) {
  const bool normals = flags & kHasNormals, colors = flags & kHasColors;
  const size_t per_vertex = 6 + (normals ? 6 : 0) + (colors ? 3 : 0);
  HOLO_RETURN_IF_ERROR(r.CheckCount("g0.num_vertices", nv, per_vertex));
  mesh->positions.resize(nv);
  for (auto& p : mesh->positions) {
    for (int c = 0; c < 3; ++c) {
      uint16_t h = 0;
      HOLO_RETURN_IF_ERROR(r.U16("g0.positions", &h));
      p[c] = HalfToFloat(h);
      if (!std::isfinite(p[c])) return DataLoss("g0.positions: not a finite number");
    }
  }
  if (normals) {
    mesh->normals.resize(nv);
    for (auto& p : mesh->normals) {
      for (int c = 0; c < 3; ++c) {
        uint16_t h = 0;
        HOLO_RETURN_IF_ERROR(r.U16("g0.normals", &h));
        p[c] = HalfToFloat(h);
        if (!std::isfinite(p[c])) return DataLoss("g0.normals: not a finite number");
      }
    }
  }
  if (colors) {
    mesh->colors.resize(nv);
    for (auto& c : mesh->colors) {
      std::span<const uint8_t> b;
      HOLO_RETURN_IF_ERROR(r.View("g0.colors", 3, &b));
      std::copy(b.begin(), b.end(), c.begin());
    }
  }
  std::span<const uint8_t> lz;
  HOLO_RETURN_IF_ERROR(r.Blob32("g0.indices", r.remaining(), &lz));
  HOLO_RETURN_IF_ERROR(r.ExpectEnd("g0"));
  // LZ4 expands at most ~255:1: a count beyond that cannot come from these bytes.
  if (uint64_t{nt} * 12 > uint64_t{lz.size()} * 255 + 16) {
    return DataLoss("g0.num_triangles: " + Str(nt) + " triangles cannot fit in " + Str(lz.size()) + " LZ4 bytes");
  }
  mesh->triangles.resize(nt);
  const int want = static_cast<int>(nt * 12);
  if (want > 0) {
    const int got = LZ4_decompress_safe(reinterpret_cast<const char*>(lz.data()),
                                        reinterpret_cast<char*>(mesh->triangles.data()), static_cast<int>(lz.size()),
                                        want);
    if (got != want) return DataLoss("g0.indices: LZ4 data is corrupt or has the wrong size");
  } else if (!lz.empty()) {
    return DataLoss("g0.indices: index bytes present for zero triangles");
  }
  for (const auto& t : mesh->triangles)
    for (uint32_t i : t)
      if (i >= nv) return DataLoss("g0.indices: vertex index " + Str(i) + " out of range (" + Str(nv) + " vertices)");
  return OkStatus();
}

// ------------------------------------------------------------------ entropy coding
//
// The static rANS token coder (protocol/rans_coder.h, shared with the depth codec D2).

using rans::kMaxSymbolsPerByte;
using rans::TokenReader;
using rans::TokenWriter;
using rans::UnZigZag;
using rans::ZigZag;

// ------------------------------------------------------------------ G1 connectivity
//
// A region-growing traversal in the spirit of Edgebreaker, kept general enough
// for any triangle soup. The coded region's border is a set of cyclic lists of
// directed "border edges" (an edge of a coded triangle whose twin is not yet
// coded). Gates are popped from a stack; for gate a→b the encoder looks for an
// uncoded triangle holding b→a and sends one symbol: BOUNDARY (none), NEW (its
// third vertex c is new: c gets the next id), LEFT (c is the origin of the
// border edge before the gate), RIGHT (c is the target of the border edge after
// the gate) or EXPLICIT (c's id follows in raw bits). When the stack runs dry,
// the next triangle is sent as a seed, each corner NEW or EXPLICIT. Encoder and
// decoder run this same Border, so they agree on every list and candidate.

enum GateSymbol : uint32_t { kBoundary = 0, kNew = 1, kLeft = 2, kRight = 3, kExplicit = 4 };
constexpr uint32_t kConnContexts = 6;  // 0..4: gate symbol after the previous gate symbol; 5: seed corners
constexpr uint32_t kSeedCtx = 5;
constexpr uint32_t kNil = UINT32_MAX;
// Border edges scanned per vertex when looking for a twin: bounds the work of
// a hostile stream; both sides stop at the same place, so they stay in step.
constexpr int kTwinScan = 16;

class Border {
 public:
  struct Node {
    uint32_t origin, target, opp;  // opp: the third vertex of the triangle holding this edge
    uint32_t prev, next;           // the border cycle
    uint32_t vprev, vnext;         // border edges leaving `origin`
    uint32_t gen;
    bool alive;
  };

  void Reset(size_t num_vertices) {
    nodes_.clear();
    free_.clear();
    stack_.clear();
    vhead_.assign(num_vertices, kNil);
  }
  void GrowVertices(size_t n) {
    if (vhead_.size() < n) vhead_.resize(n, kNil);
  }
  const Node& node(uint32_t i) const { return nodes_[i]; }

  // Pops the next live gate; false when the stack is empty.
  bool PopGate(uint32_t* g) {
    while (!stack_.empty()) {
      const auto [i, gen] = stack_.back();
      stack_.pop_back();
      if (nodes_[i].alive && nodes_[i].gen == gen) {
        *g = i;
        return true;
      }
    }
    return false;
  }

  // Adds triangle (b, a, c) across gate g = a→b; `new_vertex`: c has just been created.
  void Attach(uint32_t g, uint32_t c, bool new_vertex) {
    const Node gn = nodes_[g];
    const uint32_t e1 = New(gn.origin, c, gn.target), e2 = New(c, gn.target, gn.origin);
    if (gn.next == g) {
      Link(e1, e2);
      Link(e2, e1);
    } else {
      Link(gn.prev, e1);
      Link(e1, e2);
      Link(e2, gn.next);
    }
    Kill(g);
    // A vertex seen for the first time has no border edges but e1 and e2, so
    // neither can have a twin unless a = b: skip the searches (same result).
    if (!new_vertex || gn.origin == gn.target) {
      Zip(e1);
      Zip(e2);
    }
    Push(e1);
    Push(e2);
  }

  // Starts a new region with triangle (u, v, w).
  void Seed(uint32_t u, uint32_t v, uint32_t w) {
    const uint32_t s1 = New(u, v, w), s2 = New(v, w, u), s3 = New(w, u, v);
    Link(s1, s2);
    Link(s2, s3);
    Link(s3, s1);
    Zip(s1);
    Zip(s2);
    Zip(s3);
    Push(s3);
    Push(s2);
    Push(s1);
  }

 private:
  uint32_t New(uint32_t o, uint32_t t, uint32_t opp) {
    uint32_t i;
    if (!free_.empty()) {
      i = free_.back();
      free_.pop_back();
    } else {
      i = static_cast<uint32_t>(nodes_.size());
      nodes_.push_back(Node{0, 0, 0, kNil, kNil, kNil, kNil, 0, false});
    }
    Node& n = nodes_[i];
    n.origin = o;
    n.target = t;
    n.opp = opp;
    n.alive = true;
    n.vprev = kNil;
    n.vnext = vhead_[o];
    if (n.vnext != kNil) nodes_[n.vnext].vprev = i;
    vhead_[o] = i;
    return i;
  }
  void Link(uint32_t x, uint32_t y) {
    nodes_[x].next = y;
    nodes_[y].prev = x;
  }
  void Push(uint32_t i) {
    if (nodes_[i].alive) stack_.push_back({i, nodes_[i].gen});
  }
  void Kill(uint32_t i) {
    Node& n = nodes_[i];
    if (n.vprev != kNil) {
      nodes_[n.vprev].vnext = n.vnext;
    } else {
      vhead_[n.origin] = n.vnext;
    }
    if (n.vnext != kNil) nodes_[n.vnext].vprev = n.vprev;
    n.alive = false;
    ++n.gen;
    free_.push_back(i);
  }
  // If the twin of border edge e is a border edge too, both become interior:
  // unlink them and reconnect the cycles (this splits or merges cycles when
  // the two are not neighbours).
  void Zip(uint32_t e) {
    if (!nodes_[e].alive) return;
    const uint32_t o = nodes_[e].origin, t = nodes_[e].target;
    uint32_t x = kNil;
    uint32_t y = vhead_[t];
    for (int k = 0; y != kNil && k < kTwinScan; ++k, y = nodes_[y].vnext) {
      if (y != e && nodes_[y].target == o) {
        x = y;
        break;
      }
    }
    if (x == kNil) return;
    const uint32_t pe = nodes_[e].prev, ne = nodes_[e].next, px = nodes_[x].prev, nx = nodes_[x].next;
    if (nx == e && ne == x) {
      // a two-edge cycle closes
    } else if (nx == e) {
      Link(px, ne);
    } else if (ne == x) {
      Link(pe, nx);
    } else {
      Link(pe, nx);
      Link(px, ne);
    }
    Kill(e);
    Kill(x);
  }

  std::vector<Node> nodes_;
  std::vector<uint32_t> free_, vhead_;
  std::vector<std::pair<uint32_t, uint32_t>> stack_;
};

// How a vertex is predicted: from a + b - d (d != kNil), (a + b) / 2 (b != kNil),
// a (a != kNil) or zero. Recorded at the vertex's first use.
struct VertexPred {
  uint32_t a, b, d;
};

inline void SeedPreds(uint32_t num_before, const uint32_t* corner_ids, int new_index, VertexPred* p) {
  // new_index: which seed corner (0..2) this new vertex is. Earlier corners of
  // the same seed are known; otherwise the vertex coded before.
  if (new_index == 0) {
    *p = {num_before > 0 ? num_before - 1 : kNil, kNil, kNil};
  } else if (new_index == 1) {
    *p = {corner_ids[0], kNil, kNil};
  } else {
    *p = {corner_ids[0], corner_ids[1], kNil};
  }
}

// Outgoing edges by origin vertex: (target, third vertex, triangle), so the
// search for the triangle across a gate reads one contiguous run.
struct OutEdge {
  uint32_t target, third, tri;
};

// Working memory of the G1 coder, kept per thread between frames: a frame of
// a 64k-vertex mesh needs ~25 MB of arrays, and fresh pages for them (page
// faults, zeroing, unmapping) cost ~15% of the coding time, measured. The
// capacity only grows (to the largest mesh this thread has coded).
struct G1Scratch {
  std::vector<uint32_t> weld, unique, idx, off, fill, newid, order, tris, remap;
  std::vector<uint8_t> referenced, coded, buf;
  std::vector<OutEdge> outs;
  std::vector<VertexPred> preds;
  std::vector<std::array<uint16_t, 3>> q, ycc;
  std::vector<std::array<uint8_t, 2>> oct;
  std::vector<uint16_t> syms[2];
  std::vector<Eigen::Vector3f> normal_sum;
};
G1Scratch& G1ThreadScratch() {
  thread_local G1Scratch s;
  return s;
}

// Encodes the triangles `idx` (welded ids, `nu` vertices) and fills `order`
// (new id → welded id), `tris` (decoded triangles, new ids) and `preds`.
void EncodeConnectivity(const std::vector<uint32_t>& idx, size_t nu, TokenWriter* tw, std::vector<uint32_t>* order,
                        std::vector<uint32_t>* tris, std::vector<VertexPred>* preds) {
  const size_t nt = idx.size() / 3;
  G1Scratch& sc = G1ThreadScratch();
  using Out = OutEdge;
  std::vector<uint32_t>& off = sc.off;
  off.assign(nu + 1, 0);
  std::vector<Out>& outs = sc.outs;
  outs.resize(idx.size());
  for (uint32_t v : idx) ++off[v + 1];
  for (size_t i = 0; i < nu; ++i) off[i + 1] += off[i];
  {
    std::vector<uint32_t>& fill = sc.fill;
    fill.assign(off.begin(), off.end() - 1);
    for (size_t t = 0; t < nt; ++t) {
      const uint32_t* tri = &idx[t * 3];
      const auto tt = static_cast<uint32_t>(t);
      outs[fill[tri[0]]++] = {tri[1], tri[2], tt};
      outs[fill[tri[1]]++] = {tri[2], tri[0], tt};
      outs[fill[tri[2]]++] = {tri[0], tri[1], tt};
    }
  }
  std::vector<uint8_t>& coded = sc.coded;
  coded.assign(nt, 0);
  std::vector<uint32_t>& newid = sc.newid;
  newid.assign(nu, kNil);
  order->clear();
  order->reserve(nu);
  tris->clear();
  tris->reserve(idx.size());
  preds->clear();
  preds->reserve(nu);
  Border border;
  border.Reset(0);
  uint32_t prev_sym = 0;
  size_t seed_cursor = 0, done = 0;
  auto explicit_bits = [&]() { return static_cast<uint32_t>(std::bit_width(order->size() - 1)); };
  while (done < nt) {
    uint32_t g;
    if (!border.PopGate(&g)) {
      while (coded[seed_cursor]) ++seed_cursor;
      const uint32_t* t = &idx[seed_cursor * 3];
      coded[seed_cursor] = 1;
      ++done;
      uint32_t ids[3];
      for (int i = 0; i < 3; ++i) {
        if (newid[t[i]] == kNil) {
          tw->Put(kSeedCtx, 0);
          VertexPred p;
          SeedPreds(static_cast<uint32_t>(order->size()), ids, i, &p);
          newid[t[i]] = static_cast<uint32_t>(order->size());
          order->push_back(t[i]);
          preds->push_back(p);
          border.GrowVertices(order->size());
        } else {
          tw->Put(kSeedCtx, 1);
          tw->PutBits(newid[t[i]], explicit_bits());
        }
        ids[i] = newid[t[i]];
      }
      tris->insert(tris->end(), ids, ids + 3);
      border.Seed(ids[0], ids[1], ids[2]);
      continue;
    }
    const Border::Node gn = border.node(g);
    const uint32_t a = gn.origin, b = gn.target;
    const uint32_t oa = (*order)[a], ob = (*order)[b];
    uint32_t found = kNil, oc = kNil;
    for (uint32_t k = off[ob]; k < off[ob + 1]; ++k) {
      const Out& e = outs[k];
      if (e.target != oa || coded[e.tri]) continue;
      found = e.tri;
      oc = e.third;
      break;
    }
    if (found == kNil) {
      tw->Put(prev_sym, kBoundary);
      prev_sym = kBoundary;
      continue;
    }
    coded[found] = 1;
    ++done;
    // The gate a→c will scan c's outgoing edges a few steps from now: start
    // that (likely cache-missing) load early.
    __builtin_prefetch(&outs[off[oc]]);
    uint32_t c = newid[oc], sym;
    if (c == kNil) {
      sym = kNew;
      c = static_cast<uint32_t>(order->size());
      newid[oc] = c;
      order->push_back(oc);
      preds->push_back({a, b, gn.opp});
      border.GrowVertices(order->size());
    } else if (c == border.node(gn.prev).origin) {
      sym = kLeft;
    } else if (c == border.node(gn.next).target) {
      sym = kRight;
    } else {
      sym = kExplicit;
    }
    tw->Put(prev_sym, sym);
    if (sym == kExplicit) tw->PutBits(c, explicit_bits());
    prev_sym = sym;
    tris->push_back(b);
    tris->push_back(a);
    tris->push_back(c);
    border.Attach(g, c, sym == kNew);
  }
}

// Decodes `nt` triangles over exactly `nv` vertices.
Status DecodeConnectivity(TokenReader& tr, uint32_t nv, uint32_t nt, std::vector<uint32_t>* tris,
                          std::vector<VertexPred>* preds) {
  tris->clear();
  tris->reserve(size_t{nt} * 3);
  preds->clear();
  preds->reserve(nv);
  Border border;
  border.Reset(nv);
  uint32_t prev_sym = 0, count = 0;
  auto read_explicit = [&](uint32_t* id) {
    if (count == 0) return false;
    *id = tr.GetBits(static_cast<uint32_t>(std::bit_width(count - 1u)));
    return *id < count;
  };
  const char* kField = "g1.connectivity";
  // Every loop turn decodes one symbol, so a hostile stream ends (truncated) after MaxSymbols turns.
  uint64_t turns = 0;
  const uint64_t max_turns = tr.MaxSymbols() + 8;
  for (uint32_t done = 0; done < nt;) {
    if (++turns > max_turns || !tr.ok()) return DataLoss(std::string(kField) + ": coded data is truncated or corrupt");
    uint32_t g;
    if (!border.PopGate(&g)) {
      uint32_t ids[3];
      for (int i = 0; i < 3; ++i) {
        const uint32_t s = tr.Get(kSeedCtx);
        if (s == 0) {
          if (count >= nv) return DataLoss(std::string(kField) + ": more vertices than num_vertices");
          VertexPred p;
          SeedPreds(count, ids, i, &p);
          preds->push_back(p);
          ids[i] = count++;
        } else if (s != 1 || !read_explicit(&ids[i])) {
          return DataLoss(std::string(kField) + ": bad seed corner");
        }
      }
      tris->insert(tris->end(), ids, ids + 3);
      border.Seed(ids[0], ids[1], ids[2]);
      ++done;
      continue;
    }
    const Border::Node gn = border.node(g);
    const uint32_t sym = tr.Get(prev_sym);
    if (sym > kExplicit) return DataLoss(std::string(kField) + ": unknown gate symbol");
    prev_sym = sym;
    if (sym == kBoundary) continue;
    uint32_t c = 0;
    if (sym == kNew) {
      if (count >= nv) return DataLoss(std::string(kField) + ": more vertices than num_vertices");
      preds->push_back({gn.origin, gn.target, gn.opp});
      c = count++;
    } else if (sym == kLeft) {
      c = border.node(gn.prev).origin;
    } else if (sym == kRight) {
      c = border.node(gn.next).target;
    } else if (!read_explicit(&c)) {
      return DataLoss(std::string(kField) + ": explicit vertex out of range");
    }
    tris->push_back(gn.target);
    tris->push_back(gn.origin);
    tris->push_back(c);
    border.Attach(g, c, sym == kNew);
    ++done;
  }
  HOLO_RETURN_IF_ERROR(tr.Finish());
  if (count != nv) {
    return DataLoss("g1.num_vertices: " + Str(nv) + " vertices but triangles reference only " + Str(count));
  }
  return OkStatus();
}

// ------------------------------------------------------------------ G1 attributes

// One context per component. (Contexts from the previous residual's magnitude
// saved 0.6% but chained every symbol's table lookup to the one before:
// +15% time.)
constexpr uint32_t kPosContexts = 3;
constexpr uint32_t kColContexts = 3;  // Y, Co, Cg
constexpr uint32_t kNrmContexts = 2;

template <typename T, size_t C>
[[gnu::always_inline]] inline std::array<int32_t, C> PredictValue(const std::vector<std::array<T, C>>& vals,
                                                                  const VertexPred& p, bool parallelogram) {
  // One branch per vertex, not per component (a hot loop of the decoder).
  std::array<int32_t, C> r{};
  if (p.a == kNil) return r;
  const std::array<T, C>& A = vals[p.a];
  if (p.b == kNil) {
    for (size_t c = 0; c < C; ++c) r[c] = A[c];
    return r;
  }
  const std::array<T, C>& B = vals[p.b];
  if (p.d == kNil || !parallelogram) {
    for (size_t c = 0; c < C; ++c) r[c] = (int32_t{A[c]} + int32_t{B[c]} + 1) >> 1;
    return r;
  }
  const std::array<T, C>& D = vals[p.d];
  for (size_t c = 0; c < C; ++c) r[c] = int32_t{A[c]} + int32_t{B[c]} - int32_t{D[c]};
  return r;
}

// YCoCg-R (Malvar & Sullivan's lossless lifting), with Co and Cg optionally
// quantized to multiples of 2^shift. Stored as Y, (Co + 255) >> shift,
// (Cg + 255) >> shift (rounded). The lifting is redone with the quantized Co
// and Cg so that B stays exact and R, G are off by at most 2^(shift−1).
inline std::array<uint16_t, 3> ToYCoCg(const std::array<uint8_t, 3>& rgb, int shift) {
  const int r = rgb[0], g = rgb[1], b = rgb[2];
  const int half = shift ? 1 << (shift - 1) : 0;
  auto quant = [&](int v) { return (std::clamp(v, -255, 255) + 255 + half) >> shift; };
  const int co_s = quant(r - b), co = (co_s << shift) - 255;
  const int t = b + (co >> 1);
  const int cg_s = quant(g - t), cg = (cg_s << shift) - 255;
  const int y = std::clamp(t + (cg >> 1), 0, 255);
  return {static_cast<uint16_t>(y), static_cast<uint16_t>(co_s), static_cast<uint16_t>(cg_s)};
}
inline std::array<uint8_t, 3> FromYCoCg(const std::array<uint16_t, 3>& v, int shift) {
  const int y = v[0], co = (int{v[1]} << shift) - 255, cg = (int{v[2]} << shift) - 255;
  const int t = y - (cg >> 1), g = cg + t, b = t - (co >> 1), r = b + co;
  auto u8 = [](int x) { return static_cast<uint8_t>(std::clamp(x, 0, 255)); };
  return {u8(r), u8(g), u8(b)};
}

// Codes `vals` (nv × C components, each in [0, range)) as residuals against the
// prediction, wrapped into [-range/2, range/2) so any stream decodes to in-range values.
template <typename T, size_t C>
void EncodeResiduals(const std::vector<std::array<T, C>>& vals, const std::vector<VertexPred>& preds, int32_t range,
                     bool parallelogram, TokenWriter* tw) {
  for (size_t v = 0; v < vals.size(); ++v) {
    const auto p = PredictValue(vals, preds[v], parallelogram);
    for (size_t c = 0; c < C; ++c) {
      const int32_t pc = std::clamp(p[c], 0, range - 1);
      int32_t r = int32_t{vals[v][c]} - pc;
      if (r >= range / 2) r -= range;
      if (r < -range / 2) r += range;
      tw->PutValue(static_cast<uint32_t>(c), ZigZag(r));
    }
  }
}

template <typename T, size_t C>
Status DecodeResiduals(TokenReader& tr, const std::vector<VertexPred>& preds, int32_t range, bool parallelogram,
                       std::vector<std::array<T, C>>* vals) {
  vals->resize(preds.size());
  for (size_t v = 0; v < preds.size(); ++v) {
    const auto p = PredictValue(*vals, preds[v], parallelogram);
    for (size_t c = 0; c < C; ++c) {
      const int32_t pc = std::clamp(p[c], 0, range - 1);
      const uint32_t z = tr.GetValue(static_cast<uint32_t>(c));
      // range is a power of two: wrap by masking.
      (*vals)[v][c] = static_cast<T>(static_cast<uint32_t>(pc + UnZigZag(z)) & static_cast<uint32_t>(range - 1));
    }
  }
  return tr.Finish();
}

// Decodes two attribute streams over the same vertices in one loop (as two
// DecodeResiduals calls would). Each rANS stream alone is one long chain of
// dependent steps (table lookups, a multiply, renormalisation); two
// independent chains side by side let the CPU overlap them.
template <typename T1, size_t C1, typename T2, size_t C2>
Status DecodeResidualsPair(const std::vector<VertexPred>& preds, TokenReader& tr1, int32_t range1, bool par1,
                           std::vector<std::array<T1, C1>>* vals1, TokenReader& tr2, int32_t range2, bool par2,
                           std::vector<std::array<T2, C2>>* vals2) {
  vals1->resize(preds.size());
  vals2->resize(preds.size());
  constexpr size_t kC = C1 > C2 ? C1 : C2;
  for (size_t v = 0; v < preds.size(); ++v) {
    const auto p1 = PredictValue(*vals1, preds[v], par1);
    const auto p2 = PredictValue(*vals2, preds[v], par2);
    for (size_t c = 0; c < kC; ++c) {
      if (c < C1) {
        const int32_t pc = std::clamp(p1[c], 0, range1 - 1);
        const uint32_t z = tr1.GetValue(static_cast<uint32_t>(c));
        (*vals1)[v][c] = static_cast<T1>(static_cast<uint32_t>(pc + UnZigZag(z)) & static_cast<uint32_t>(range1 - 1));
      }
      if (c < C2) {
        const int32_t pc = std::clamp(p2[c], 0, range2 - 1);
        const uint32_t z = tr2.GetValue(static_cast<uint32_t>(c));
        (*vals2)[v][c] = static_cast<T2>(static_cast<uint32_t>(pc + UnZigZag(z)) & static_cast<uint32_t>(range2 - 1));
      }
    }
  }
  HOLO_RETURN_IF_ERROR(tr1.Finish());
  return tr2.Finish();
}

// Vertex normals of `mesh` from its triangles (unit length; +Z where undefined).
void SmoothedAreaWeightedNormals(Mesh* mesh) {
  mesh->normals.assign(mesh->num_vertices(), Eigen::Vector3f::Zero());
  for (const auto& t : mesh->triangles) {
    const Eigen::Vector3f& p0 = mesh->positions[t[0]];
    const Eigen::Vector3f n = (mesh->positions[t[1]] - p0).cross(mesh->positions[t[2]] - p0);
    for (uint32_t v : t) mesh->normals[v] += n;
  }
  // One smoothing pass over the unnormalized sums: each vertex takes the sum
  // over its triangles of their corners' sums. Marching-cubes meshes have
  // clusters of sliver triangles (a vertex next to a lattice corner) whose
  // quantized normals are noise; their small areas let the neighbouring large
  // triangles decide. Measured on the 6 mm blob: mean error vs the SDF normals
  // 8.0° → 4.0°, 99th percentile 70° → 12° (unquantized area-weighted: 3.4°, 11°).
  std::vector<Eigen::Vector3f>& sum = G1ThreadScratch().normal_sum;
  sum.assign(mesh->num_vertices(), Eigen::Vector3f::Zero());
  for (const auto& t : mesh->triangles) {
    const Eigen::Vector3f n = mesh->normals[t[0]] + mesh->normals[t[1]] + mesh->normals[t[2]];
    for (uint32_t v : t) sum[v] += n;
  }
  mesh->normals.swap(sum);
  for (auto& n : mesh->normals) {
    const float len = n.norm();
    n = len > 0 ? Eigen::Vector3f(n / len) : Eigen::Vector3f::UnitZ();
  }
}

void AppendBlob32(std::vector<uint8_t>* out, const std::vector<uint8_t>& b) {
  ByteWriter w(out);
  w.U32(static_cast<uint32_t>(b.size()));
  out->insert(out->end(), b.begin(), b.end());
}

Status EncodeG1(const Mesh& mesh, const GeometryEncodeOptions& o, std::vector<uint8_t>* out,
                std::vector<uint32_t>* vertex_map) {
  G1Scratch& sc = G1ThreadScratch();
  std::vector<uint32_t>&weld = sc.weld, &unique = sc.unique;
  WeldExactPositions(mesh, &weld, &unique);
  const bool send_normals = o.normals == NormalMode::kTransmit && !mesh.normals.empty();
  const bool recompute = o.normals == NormalMode::kRecompute && !mesh.normals.empty();
  const bool colors = o.colors && !mesh.colors.empty();
  const size_t nt = mesh.num_triangles();
  const size_t nu = unique.size();
  std::vector<uint32_t>& idx = sc.idx;
  idx.resize(nt * 3);
  std::vector<uint8_t>& referenced = sc.referenced;
  referenced.assign(nu, 0);
  for (size_t t = 0; t < nt; ++t)
    for (int c = 0; c < 3; ++c) referenced[idx[t * 3 + c] = weld[mesh.triangles[t][c]]] = 1;

  // Bounding box and grid of the referenced vertices.
  Eigen::Vector3f lo = Eigen::Vector3f::Constant(std::numeric_limits<float>::max());
  Eigen::Vector3f hi = -lo;
  for (size_t u = 0; u < nu; ++u) {
    if (!referenced[u]) continue;
    lo = lo.cwiseMin(mesh.positions[unique[u]]);
    hi = hi.cwiseMax(mesh.positions[unique[u]]);
  }
  if (nt == 0) lo = hi = Eigen::Vector3f::Zero();
  const float step = o.position_step_m;
  const float extent = (hi - lo).maxCoeff();
  if (extent / step > 65534.0f) {
    return InvalidArgument("mesh extent " + std::to_string(extent) + " m needs a position step of at least " +
                           std::to_string(extent / 65535.0f) + " m");
  }

  TokenWriter conn(kConnContexts, nt + nt / 4, &sc.syms[0]);
  std::vector<uint32_t>&order = sc.order, &tris = sc.tris;
  std::vector<VertexPred>& preds = sc.preds;
  EncodeConnectivity(idx, nu, &conn, &order, &tris, &preds);
  const size_t nv = order.size();

  const uint8_t flags = static_cast<uint8_t>((send_normals ? kHasNormals : 0) | (colors ? kHasColors : 0) |
                                             (recompute ? kRecomputeNormals : 0));
  ByteWriter w(out);
  const size_t prefix_at = out->size();
  WritePrefix(w, GeometryCodec::kG1, flags, nv, nt);
  // Shift the grid so that the most common fractional grid position lands on
  // a grid point. The vertices of a marching-cubes mesh lie on lattice edges,
  // so most of their coordinates are lattice values, which then quantize
  // almost exactly (blob: RMS error 0.54 → 0.39 mm). Costs at most one step of extent.
  for (int c = 0; c < 3; ++c) {
    uint32_t bins[32] = {};
    const size_t stride = std::max<size_t>(1, nu / 4096);
    for (size_t u = 0; u < nu; u += stride) {
      if (!referenced[u]) continue;
      const float g = (mesh.positions[unique[u]][c] - lo[c]) / step;
      ++bins[std::clamp(static_cast<int>((g - std::floor(g)) * 32.0f), 0, 31)];
    }
    const auto mode = static_cast<int>(std::max_element(bins, bins + 32) - bins);
    lo[c] -= (1.0f - (static_cast<float>(mode) + 0.5f) / 32.0f) * step;
  }
  for (int c = 0; c < 3; ++c) w.F32(lo[c]);
  w.F32(step);
  w.U8(static_cast<uint8_t>(colors ? o.chroma_shift : 0));

  std::vector<uint8_t>& buf = sc.buf;
  buf.clear();
  conn.Finish(&buf);
  AppendBlob32(out, buf);

  // Gather every attribute in traversal order in one pass (the reads are scattered).
  std::vector<std::array<uint16_t, 3>>&q = sc.q, &ycc = sc.ycc;
  q.resize(nv);
  ycc.resize(colors ? nv : 0);
  std::vector<std::array<uint8_t, 2>>& oct = sc.oct;
  oct.resize(send_normals ? nv : 0);
  const float inv_step = 1.0f / step;
  for (size_t v = 0; v < nv; ++v) {
    const uint32_t src = unique[order[v]];
    if (v + 16 < nv) __builtin_prefetch(&mesh.positions[unique[order[v + 16]]]);
    const Eigen::Vector3f& p = mesh.positions[src];
    for (int c = 0; c < 3; ++c) {
      // (p − lo) ≥ 0: adding ½ and truncating rounds to the nearest grid point.
      q[v][c] = static_cast<uint16_t>(std::min(65535.0f, (p[c] - lo[c]) * inv_step + 0.5f));
    }
    if (colors) ycc[v] = ToYCoCg(mesh.colors[src], o.chroma_shift);
    if (send_normals) {
      float a, b;
      OctEncode(mesh.normals[src], &a, &b);
      oct[v] = {static_cast<uint8_t>(std::lround((a * 0.5f + 0.5f) * 255.0f)),
                static_cast<uint8_t>(std::lround((b * 0.5f + 0.5f) * 255.0f))};
    }
  }
  {
    TokenWriter tw(kPosContexts, nv * 3, &sc.syms[1]);
    EncodeResiduals(q, preds, 65536, true, &tw);
    buf.clear();
    tw.Finish(&buf);
    AppendBlob32(out, buf);
  }
  if (send_normals) {
    TokenWriter tw(kNrmContexts, nv * 2, &sc.syms[0]);
    EncodeResiduals(oct, preds, 256, false, &tw);
    buf.clear();
    tw.Finish(&buf);
    AppendBlob32(out, buf);
  }
  if (colors) {
    // Smooth colour fields favour the parallelogram, noisy ones the mean:
    // estimate both on every 4th vertex (bit lengths of the residuals) and flag the choice.
    uint64_t cost[2] = {0, 0};
    for (size_t v = 0; v < nv; v += 4) {
      for (int m = 0; m < 2; ++m) {
        const auto p = PredictValue(ycc, preds[v], m == 0);
        for (int c = 0; c < 3; ++c) cost[m] += std::bit_width(ZigZag(int32_t{ycc[v][c]} - std::clamp(p[c], 0, 511)));
      }
    }
    const bool color_by_mean = cost[1] < cost[0];
    if (color_by_mean) (*out)[prefix_at + 1] |= kColorsByMean;
    TokenWriter tw(kColContexts, nv * 3, &sc.syms[1]);
    EncodeResiduals(ycc, preds, 512, !color_by_mean, &tw);
    buf.clear();
    tw.Finish(&buf);
    AppendBlob32(out, buf);
  }

  if (vertex_map) {
    std::vector<uint32_t>& remap = sc.remap;
    remap.assign(nu, kNil);
    for (size_t v = 0; v < nv; ++v) remap[order[v]] = static_cast<uint32_t>(v);
    vertex_map->resize(mesh.num_vertices());
    for (size_t i = 0; i < mesh.num_vertices(); ++i) (*vertex_map)[i] = remap[weld[i]];
  }
  return OkStatus();
}

Status DecodeG1(ByteReader& r, uint8_t flags, uint32_t nv, uint32_t nt, Mesh* mesh) {
  const bool normals = flags & kHasNormals, colors = flags & kHasColors, recompute = flags & kRecomputeNormals;
  if (normals && recompute) return DataLoss("geometry.flags: normals both sent and recomputed");
  if ((flags & kColorsByMean) && !colors) return DataLoss("geometry.flags: colour prediction flagged without colours");
  float origin[3], step = 0;
  for (float& f : origin) HOLO_RETURN_IF_ERROR(r.F32("g1.origin", &f));
  HOLO_RETURN_IF_ERROR(r.F32("g1.step", &step));
  uint8_t chroma_shift = 0;
  HOLO_RETURN_IF_ERROR(r.U8("g1.chroma_shift", &chroma_shift));
  if (chroma_shift > 3 || (chroma_shift && !colors)) return DataLoss("g1.chroma_shift: must be 0..3, and 0 without colours");
  if (!(step >= 1e-5f && step <= 0.1f)) return DataLoss("g1.step: must be in [1e-5, 0.1] m");
  for (float f : origin)
    if (!std::isfinite(f) || std::abs(f) > 1e6f) return DataLoss("g1.origin: not a finite coordinate");
  if (uint64_t{nv} > uint64_t{nt} * 3) {
    return DataLoss("g1.num_vertices: " + Str(nv) + " vertices cannot all be referenced by " + Str(nt) + " triangles");
  }
  std::span<const uint8_t> conn_b, pos_b, nrm_b, col_b;
  HOLO_RETURN_IF_ERROR(r.Blob32("g1.connectivity", r.remaining(), &conn_b));
  HOLO_RETURN_IF_ERROR(r.Blob32("g1.positions", r.remaining(), &pos_b));
  if (normals) HOLO_RETURN_IF_ERROR(r.Blob32("g1.normals", r.remaining(), &nrm_b));
  if (colors) HOLO_RETURN_IF_ERROR(r.Blob32("g1.colors", r.remaining(), &col_b));
  HOLO_RETURN_IF_ERROR(r.ExpectEnd("g1"));

  TokenReader conn;
  HOLO_RETURN_IF_ERROR(conn.Init(conn_b, kConnContexts, "g1.connectivity"));
  // Every triangle costs at least one connectivity symbol, every vertex three position symbols.
  if (nt > 0 && uint64_t{nt} > conn.MaxSymbols()) {
    return DataLoss("g1.num_triangles: " + Str(nt) + " triangles cannot fit in " + Str(conn_b.size()) + " bytes");
  }
  TokenReader pos;
  HOLO_RETURN_IF_ERROR(pos.Init(pos_b, kPosContexts, "g1.positions"));
  if (uint64_t{nv} * 3 > pos.MaxSymbols()) {
    return DataLoss("g1.num_vertices: " + Str(nv) + " vertices cannot fit in " + Str(pos_b.size()) + " bytes");
  }
  G1Scratch& sc = G1ThreadScratch();
  std::vector<uint32_t>& tris = sc.tris;
  std::vector<VertexPred>& preds = sc.preds;
  HOLO_RETURN_IF_ERROR(DecodeConnectivity(conn, nv, nt, &tris, &preds));

  std::vector<std::array<uint16_t, 3>>&q = sc.q, &ycc = sc.ycc;
  if (colors) {
    TokenReader tr;
    HOLO_RETURN_IF_ERROR(tr.Init(col_b, kColContexts, "g1.colors"));
    HOLO_RETURN_IF_ERROR(
        DecodeResidualsPair(preds, pos, 65536, true, &q, tr, 512, !(flags & kColorsByMean), &ycc));
    mesh->colors.resize(nv);
    for (size_t v = 0; v < nv; ++v) mesh->colors[v] = FromYCoCg(ycc[v], chroma_shift);
  } else {
    HOLO_RETURN_IF_ERROR(DecodeResiduals(pos, preds, 65536, true, &q));
  }
  mesh->positions.resize(nv);
  for (size_t v = 0; v < nv; ++v)
    for (int c = 0; c < 3; ++c) mesh->positions[v][c] = origin[c] + static_cast<float>(q[v][c]) * step;
  if (normals) {
    TokenReader tr;
    HOLO_RETURN_IF_ERROR(tr.Init(nrm_b, kNrmContexts, "g1.normals"));
    std::vector<std::array<uint8_t, 2>>& oct = sc.oct;
    HOLO_RETURN_IF_ERROR(DecodeResiduals(tr, preds, 256, false, &oct));
    mesh->normals.resize(nv);
    for (size_t v = 0; v < nv; ++v) {
      mesh->normals[v] = OctDecode(oct[v][0] / 255.0f * 2.0f - 1.0f, oct[v][1] / 255.0f * 2.0f - 1.0f);
    }
  }
  mesh->triangles.resize(nt);
  if (nt > 0) std::memcpy(mesh->triangles.data(), tris.data(), tris.size() * 4);
  if (recompute) SmoothedAreaWeightedNormals(mesh);
  return OkStatus();
}

}  // namespace

Status GeometryEncodeOptions::Check() const {
  if (codec != GeometryCodec::kG0 && codec != GeometryCodec::kG1) return InvalidArgument("codec must be G0 or G1 (G3 codes a distance grid: EncodeSurface)");
  if (chroma_shift < 0 || chroma_shift > 3) {
    return InvalidArgument("chroma_shift must be in [0, 3], got " + std::to_string(chroma_shift));
  }
  if (!(position_step_m >= 1e-5f && position_step_m <= 0.1f)) {
    return InvalidArgument("position_step_m must be in [1e-5, 0.1], got " + std::to_string(position_step_m));
  }
  return OkStatus();
}

Status CheckMesh(const Mesh& mesh) {
  const size_t n = mesh.positions.size();
  if (!mesh.normals.empty() && mesh.normals.size() != n) {
    return DataLoss("mesh has " + Str(mesh.normals.size()) + " normals for " + Str(n) + " vertices");
  }
  if (!mesh.colors.empty() && mesh.colors.size() != n) {
    return DataLoss("mesh has " + Str(mesh.colors.size()) + " colors for " + Str(n) + " vertices");
  }
  for (size_t i = 0; i < n; ++i)
    if (!mesh.positions[i].allFinite()) return DataLoss("vertex " + Str(i) + " is not finite");
  for (size_t i = 0; i < mesh.normals.size(); ++i)
    if (!mesh.normals[i].allFinite()) return DataLoss("normal " + Str(i) + " is not finite");
  for (size_t t = 0; t < mesh.triangles.size(); ++t)
    for (uint32_t i : mesh.triangles[t])
      if (i >= n) return DataLoss("triangle " + Str(t) + " references vertex " + Str(i) + " of " + Str(n));
  return OkStatus();
}

void RecomputeNormals(Mesh* mesh) { SmoothedAreaWeightedNormals(mesh); }

void ClearMesh(Mesh* mesh) {
  mesh->positions.clear();
  mesh->normals.clear();
  mesh->colors.clear();
  mesh->triangles.clear();
}

void OctEncode(const Eigen::Vector3f& n, float* u, float* v) {
  const float s = std::abs(n.x()) + std::abs(n.y()) + std::abs(n.z());
  if (!(s > 0)) {
    *u = 0;
    *v = 0;
    return;
  }
  float x = n.x() / s, y = n.y() / s;
  if (n.z() < 0) {
    const float ox = x, oy = y;
    x = (1.0f - std::abs(oy)) * (ox >= 0 ? 1.0f : -1.0f);
    y = (1.0f - std::abs(ox)) * (oy >= 0 ? 1.0f : -1.0f);
  }
  *u = std::clamp(x, -1.0f, 1.0f);
  *v = std::clamp(y, -1.0f, 1.0f);
}

Eigen::Vector3f OctDecode(float u, float v) {
  Eigen::Vector3f n(u, v, 1.0f - std::abs(u) - std::abs(v));
  if (n.z() < 0) {
    const float ox = n.x(), oy = n.y();
    n.x() = (1.0f - std::abs(oy)) * (ox >= 0 ? 1.0f : -1.0f);
    n.y() = (1.0f - std::abs(ox)) * (oy >= 0 ? 1.0f : -1.0f);
  }
  return n.normalized();
}

Status EncodeGeometry(const Mesh& mesh, const GeometryEncodeOptions& options, std::vector<uint8_t>* out,
                      std::vector<uint32_t>* vertex_map) {
  HOLO_RETURN_IF_ERROR(options.Check());
  HOLO_RETURN_IF_ERROR(CheckEncodable(mesh));
  if (options.codec == GeometryCodec::kG0) return EncodeG0(mesh, options, out, vertex_map);
  return EncodeG1(mesh, options, out, vertex_map);
}

StatusOr<GeometryCodec> PeekGeometryCodec(std::span<const uint8_t> blob) {
  if (blob.empty()) return DataLoss("geometry.codec: empty blob");
  if (blob[0] != 1 && blob[0] != 2 && blob[0] != 4) return DataLoss("geometry.codec: unknown geometry codec " + Str(blob[0]));
  return static_cast<GeometryCodec>(blob[0]);
}

Status DecodeGeometry(std::span<const uint8_t> blob, Mesh* mesh, const Limits& limits) {
  ClearMesh(mesh);
  ByteReader r(blob);
  uint8_t codec = 0, flags = 0;
  uint16_t reserved = 0;
  uint32_t nv = 0, nt = 0;
  HOLO_RETURN_IF_ERROR(r.U8("geometry.codec", &codec));
  HOLO_RETURN_IF_ERROR(r.U8("geometry.flags", &flags));
  HOLO_RETURN_IF_ERROR(r.U16("geometry.reserved", &reserved));
  HOLO_RETURN_IF_ERROR(r.U32("geometry.num_vertices", &nv));
  HOLO_RETURN_IF_ERROR(r.U32("geometry.num_triangles", &nt));
  if (flags & ~(kHasNormals | kHasColors | kRecomputeNormals | kColorsByMean)) {
    return DataLoss("geometry.flags: unknown flag bits set");
  }
  if (codec != static_cast<uint8_t>(GeometryCodec::kG1) && (flags & (kRecomputeNormals | kColorsByMean))) {
    return DataLoss("geometry.flags: bits 2-3 are G1 only");
  }
  if (reserved != 0) return DataLoss("geometry.reserved: must be zero");
  if (nv > limits.max_vertices) {
    return DataLoss("geometry.num_vertices: " + Str(nv) + " exceeds limit " + Str(limits.max_vertices));
  }
  if (nt > limits.max_triangles) {
    return DataLoss("geometry.num_triangles: " + Str(nt) + " exceeds limit " + Str(limits.max_triangles));
  }
  Status s;
  if (codec == static_cast<uint8_t>(GeometryCodec::kG0)) {
    s = DecodeG0(r, flags, nv, nt, mesh);
  } else if (codec == static_cast<uint8_t>(GeometryCodec::kG1)) {
    s = DecodeG1(r, flags, nv, nt, mesh);
  } else if (codec == static_cast<uint8_t>(GeometryCodec::kG3)) {
    s = flags != 0 ? DataLoss("geometry.flags: must be 0 for G3") : internal::DecodeSurfaceBody(r, nv, nt, mesh);
  } else {
    s = DataLoss("geometry.codec: unknown geometry codec " + Str(codec));
  }
  if (!s.ok()) {
    ClearMesh(mesh);
    return s;
  }
  return OkStatus();
}

}  // namespace holo::protocol
