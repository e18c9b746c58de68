// Geometry codecs of MeshFrame (PROTOCOL.md §7): G0, G1 and G3, a port of
// protocol/geometry_codec.cc's and protocol/surface_codec.cc's decoders. Safe
// on untrusted input: every count is checked against its limit and the bytes
// that remain before allocation; malformed data throws a DecodeError naming
// the field.
//
// The result: { positions: Float32Array(3n), normals: Float32Array(3n) | null,
//               colors: Uint8Array(3n) | null, indices: Uint32Array(3t) }.

import { Reader, fail, lz4DecodeBlock } from './bytes.js';
import { EDGE_AXIS, EDGE_LOW, mcCases } from './marching_cubes.js';

export const LIMITS = { maxVertices: 2 << 20, maxTriangles: 4 << 20 };

const HAS_NORMALS = 1, HAS_COLORS = 2, RECOMPUTE_NORMALS = 4, COLORS_BY_MEAN = 8;
const TOKENS = 64, PROB_BITS = 12, PROB_SCALE = 1 << PROB_BITS, MAX_FREQ = PROB_SCALE - 64;
const MAX_SYMBOLS_PER_BYTE = 353, RANS_LOW = 1 << 23;
const NIL = 0xffffffff;

// ---------------------------------------------------------------- rANS tokens

class TokenReader {
  constructor(data, contexts, field) {
    this.field = field;
    this.ok = true;
    this.tables = [];
    let pos = 0;
    const byte = () => {
      if (pos >= data.length) fail(`${field}: truncated frequency table`);
      return data[pos++];
    };
    for (let c = 0; c < contexts; ++c) {
      const n = pos < data.length ? data[pos++] : fail(`${field}: bad frequency table ${c}`);
      if (n > TOKENS) fail(`${field}: bad frequency table ${c}`);
      if (n === 0) {
        this.tables.push(null);
        continue;
      }
      const freq = new Uint16Array(TOKENS), start = new Uint16Array(TOKENS), sym = new Uint8Array(PROB_SCALE);
      let cum = 0;
      for (let t = 0; t < n; ++t) {
        const lo = byte();
        let fr = lo;
        if (lo & 0x80) fr = (lo & 0x7f) | (byte() << 7);
        if (fr > MAX_FREQ || cum + fr > PROB_SCALE) fail(`${field}: frequencies exceed the scale`);
        freq[t] = fr;
        start[t] = cum;
        sym.fill(t, cum, cum + fr);
        cum += fr;
      }
      if (cum !== PROB_SCALE) fail(`${field}: frequencies do not sum to 4096`);
      this.tables.push({ freq, start, sym });
    }
    if (data.length - pos < 4) fail(`${field}: missing rANS length`);
    const n = (data[pos] | (data[pos + 1] << 8) | (data[pos + 2] << 16) | (data[pos + 3] << 24)) >>> 0;
    pos += 4;
    if (n > data.length - pos) fail(`${field}: rANS length out of range`);
    // The rANS bytes plus two zero bytes of padding (as the C++ reader).
    this.rans = new Uint8Array(n + 2);
    this.rans.set(data.subarray(pos, pos + n));
    this.ransEnd = n;
    this.bits = data.subarray(pos + n);
    if (n < 8) fail(`${field}: rANS length out of range`);
    const r = this.rans;
    this.x0 = (r[0] | (r[1] << 8) | (r[2] << 16) | (r[3] << 24)) >>> 0;
    this.x1 = (r[4] | (r[5] << 8) | (r[6] << 16) | (r[7] << 24)) >>> 0;
    if (this.x0 < RANS_LOW || this.x1 < RANS_LOW) fail(`${field}: bad rANS state`);
    this.rpos = 8;
    this.bpos = 0;
    this.acc = 0;  // < 2^34 bits are never held: n ≤ 26 plus 8
    this.nacc = 0;
  }
  maxSymbols() {
    return (this.ransEnd + 1) * MAX_SYMBOLS_PER_BYTE;
  }
  get(ctx) {
    const tb = this.tables[ctx];
    if (!tb) {
      this.ok = false;
      return 0;
    }
    let x = this.x0;
    const slot = x & (PROB_SCALE - 1);
    const s = tb.sym[slot];
    x = tb.freq[s] * (x >>> PROB_BITS) + slot - tb.start[s];
    for (let k = 0; k < 2 && x < RANS_LOW; ++k) x = ((x << 8) | this.rans[this.rpos++]) >>> 0;
    this.x0 = this.x1;
    this.x1 = x;
    if (this.rpos > this.ransEnd) {
      this.ok = false;
      this.rpos = this.ransEnd;
    }
    return s;
  }
  getBits(n) {
    while (this.nacc < n) {
      if (this.bpos >= this.bits.length) {
        this.ok = false;
        return 0;
      }
      this.acc += this.bits[this.bpos++] * 2 ** this.nacc;
      this.nacc += 8;
    }
    const m = 2 ** n;
    const v = this.acc % m;
    this.acc = Math.floor(this.acc / m);
    this.nacc -= n;
    return v;
  }
  getValue(ctx) {
    const tok = this.get(ctx);
    if (tok < 16) return tok;
    const n = ((tok - 16) >> 1) + 5;
    return 2 ** (n - 1) + (tok & 1) * 2 ** (n - 2) + this.getBits(n - 2);
  }
  finish() {
    if (!this.ok) fail(`${this.field}: coded data is truncated or corrupt`);
    if (this.x0 !== RANS_LOW || this.x1 !== RANS_LOW || this.rpos !== this.ransEnd) {
      fail(`${this.field}: rANS data does not end cleanly`);
    }
    if (this.bits.length - this.bpos > 0) fail(`${this.field}: raw bits left over`);
  }
}

function bitWidth(v) {
  return v === 0 ? 0 : 32 - Math.clz32(v);
}

// ---------------------------------------------------------------- G1 connectivity

const BOUNDARY = 0, NEW = 1, LEFT = 2, RIGHT = 3, EXPLICIT = 4;
const CONN_CONTEXTS = 6, SEED_CTX = 5, TWIN_SCAN = 16;

// The border of the decoded region (PROTOCOL.md §7 "Connectivity"), in typed
// arrays that grow by doubling.
class Border {
  constructor(numVertices) {
    this.cap = 0;
    this.count = 0;
    this.grow(1024);
    this.free = [];
    this.stack = [];  // pairs (node, generation)
    this.vhead = new Uint32Array(numVertices).fill(NIL);
  }
  grow(cap) {
    const fields = ['origin', 'target', 'opp', 'prev', 'next', 'vprev', 'vnext', 'gen'];
    for (const f of fields) {
      const a = new Uint32Array(cap);
      if (this[f]) a.set(this[f]);
      this[f] = a;
    }
    const alive = new Uint8Array(cap);
    if (this.alive) alive.set(this.alive);
    this.alive = alive;
    this.cap = cap;
  }
  popGate() {
    const st = this.stack;
    while (st.length) {
      const gen = st.pop(), i = st.pop();
      if (this.alive[i] && this.gen[i] === gen) return i;
    }
    return NIL;
  }
  newEdge(o, t, opp) {
    let i;
    if (this.free.length) {
      i = this.free.pop();
    } else {
      if (this.count === this.cap) this.grow(this.cap * 2);
      i = this.count++;
      this.gen[i] = 0;
    }
    this.origin[i] = o;
    this.target[i] = t;
    this.opp[i] = opp;
    this.alive[i] = 1;
    this.vprev[i] = NIL;
    const h = this.vhead[o];
    this.vnext[i] = h;
    if (h !== NIL) this.vprev[h] = i;
    this.vhead[o] = i;
    return i;
  }
  link(x, y) {
    this.next[x] = y;
    this.prev[y] = x;
  }
  push(i) {
    if (this.alive[i]) this.stack.push(i, this.gen[i]);
  }
  kill(i) {
    const vp = this.vprev[i], vn = this.vnext[i];
    if (vp !== NIL) this.vnext[vp] = vn;
    else this.vhead[this.origin[i]] = vn;
    if (vn !== NIL) this.vprev[vn] = vp;
    this.alive[i] = 0;
    this.gen[i] = (this.gen[i] + 1) >>> 0;
    this.free.push(i);
  }
  zip(e) {
    if (!this.alive[e]) return;
    const o = this.origin[e], t = this.target[e];
    let x = NIL;
    let y = this.vhead[t];
    for (let k = 0; y !== NIL && k < TWIN_SCAN; ++k, y = this.vnext[y]) {
      if (y !== e && this.target[y] === o) {
        x = y;
        break;
      }
    }
    if (x === NIL) return;
    const pe = this.prev[e], ne = this.next[e], px = this.prev[x], nx = this.next[x];
    if (nx === e && ne === x) {
      // a two-edge cycle closes
    } else if (nx === e) {
      this.link(px, ne);
    } else if (ne === x) {
      this.link(pe, nx);
    } else {
      this.link(pe, nx);
      this.link(px, ne);
    }
    this.kill(e);
    this.kill(x);
  }
  attach(g, c, newVertex) {
    const go = this.origin[g], gt = this.target[g], gp = this.prev[g], gnx = this.next[g];
    const e1 = this.newEdge(go, c, gt), e2 = this.newEdge(c, gt, go);
    if (gnx === g) {
      this.link(e1, e2);
      this.link(e2, e1);
    } else {
      this.link(gp, e1);
      this.link(e1, e2);
      this.link(e2, gnx);
    }
    this.kill(g);
    if (!newVertex || go === gt) {
      this.zip(e1);
      this.zip(e2);
    }
    this.push(e1);
    this.push(e2);
  }
  seed(u, v, w) {
    const s1 = this.newEdge(u, v, w), s2 = this.newEdge(v, w, u), s3 = this.newEdge(w, u, v);
    this.link(s1, s2);
    this.link(s2, s3);
    this.link(s3, s1);
    this.zip(s1);
    this.zip(s2);
    this.zip(s3);
    this.push(s3);
    this.push(s2);
    this.push(s1);
  }
}

// Decodes nt triangles over exactly nv vertices; returns the triangles and
// per vertex its predictors (a, b, d; NIL = none).
function decodeConnectivity(tr, nv, nt) {
  const field = 'g1.connectivity';
  const tris = new Uint32Array(nt * 3);
  const pa = new Uint32Array(nv), pb = new Uint32Array(nv), pd = new Uint32Array(nv);
  const border = new Border(nv);
  let prevSym = 0, count = 0, ti = 0;
  const readExplicit = () => {
    if (count === 0) return NIL;
    const id = tr.getBits(bitWidth(count - 1));
    return id < count ? id : NIL;
  };
  let turns = 0;
  const maxTurns = tr.maxSymbols() + 8;
  const ids = [0, 0, 0];
  for (let done = 0; done < nt;) {
    if (++turns > maxTurns || !tr.ok) fail(`${field}: coded data is truncated or corrupt`);
    const g = border.popGate();
    if (g === NIL) {
      for (let i = 0; i < 3; ++i) {
        const s = tr.get(SEED_CTX);
        if (s === 0) {
          if (count >= nv) fail(`${field}: more vertices than num_vertices`);
          if (i === 0) {
            pa[count] = count > 0 ? count - 1 : NIL;
            pb[count] = NIL;
          } else if (i === 1) {
            pa[count] = ids[0];
            pb[count] = NIL;
          } else {
            pa[count] = ids[0];
            pb[count] = ids[1];
          }
          pd[count] = NIL;
          ids[i] = count++;
        } else {
          const id = s === 1 ? readExplicit() : NIL;
          if (id === NIL) fail(`${field}: bad seed corner`);
          ids[i] = id;
        }
      }
      tris[ti++] = ids[0];
      tris[ti++] = ids[1];
      tris[ti++] = ids[2];
      border.seed(ids[0], ids[1], ids[2]);
      ++done;
      continue;
    }
    const go = border.origin[g], gt = border.target[g];
    const sym = tr.get(prevSym);
    if (sym > EXPLICIT) fail(`${field}: unknown gate symbol`);
    prevSym = sym;
    if (sym === BOUNDARY) continue;
    let c;
    if (sym === NEW) {
      if (count >= nv) fail(`${field}: more vertices than num_vertices`);
      pa[count] = go;
      pb[count] = gt;
      pd[count] = border.opp[g];
      c = count++;
    } else if (sym === LEFT) {
      c = border.origin[border.prev[g]];
    } else if (sym === RIGHT) {
      c = border.target[border.next[g]];
    } else {
      c = readExplicit();
      if (c === NIL) fail(`${field}: explicit vertex out of range`);
    }
    tris[ti++] = gt;
    tris[ti++] = go;
    tris[ti++] = c;
    border.attach(g, c, sym === NEW);
    ++done;
  }
  tr.finish();
  if (count !== nv) fail(`g1.num_vertices: ${nv} vertices but triangles reference only ${count}`);
  return { tris, pa, pb, pd };
}

// ---------------------------------------------------------------- G1 attributes

// Decodes C components per vertex (each in [0, range), range a power of two)
// as residuals against the prediction into `out` (length nv × C).
function decodeResiduals(tr, preds, C, range, parallelogram, out) {
  const { pa, pb, pd } = preds;
  const nv = pa.length, mask = range - 1;
  const p = [0, 0, 0];
  for (let v = 0; v < nv; ++v) {
    const a = pa[v], b = pb[v], d = pd[v];
    for (let c = 0; c < C; ++c) {
      let pr;
      if (a === NIL) pr = 0;
      else if (b === NIL) pr = out[a * C + c];
      else if (d === NIL || !parallelogram) pr = (out[a * C + c] + out[b * C + c] + 1) >> 1;
      else pr = out[a * C + c] + out[b * C + c] - out[d * C + c];
      p[c] = pr < 0 ? 0 : pr > range - 1 ? range - 1 : pr;
    }
    for (let c = 0; c < C; ++c) {
      const z = tr.getValue(c);
      // UnZigZag of a 32-bit value; z < 2^28 here.
      const r = z % 2 ? -(z + 1) / 2 : z / 2;
      out[v * C + c] = (p[c] + r) & mask;
    }
  }
  tr.finish();
}

function clamp255(x) {
  return x < 0 ? 0 : x > 255 ? 255 : x;
}

// The normals the G1 decoder computes (PROTOCOL.md §7): area-weighted face
// normals summed per vertex, smoothed once, normalized; in float32 steps as
// the C++ decoder.
export function recomputeNormals(positions, indices, nv) {
  const f = Math.fround;
  const n0 = new Float32Array(nv * 3);
  const nt = indices.length / 3;
  for (let t = 0; t < nt; ++t) {
    const i0 = indices[3 * t] * 3, i1 = indices[3 * t + 1] * 3, i2 = indices[3 * t + 2] * 3;
    const ax = f(positions[i1] - positions[i0]), ay = f(positions[i1 + 1] - positions[i0 + 1]);
    const az = f(positions[i1 + 2] - positions[i0 + 2]);
    const bx = f(positions[i2] - positions[i0]), by = f(positions[i2 + 1] - positions[i0 + 1]);
    const bz = f(positions[i2 + 2] - positions[i0 + 2]);
    const nx = f(f(ay * bz) - f(az * by)), ny = f(f(az * bx) - f(ax * bz)), nz = f(f(ax * by) - f(ay * bx));
    for (const i of [i0, i1, i2]) {
      n0[i] += nx;
      n0[i + 1] += ny;
      n0[i + 2] += nz;
    }
  }
  const sum = new Float32Array(nv * 3);
  for (let t = 0; t < nt; ++t) {
    const i0 = indices[3 * t] * 3, i1 = indices[3 * t + 1] * 3, i2 = indices[3 * t + 2] * 3;
    const sx = f(f(n0[i0] + n0[i1]) + n0[i2]), sy = f(f(n0[i0 + 1] + n0[i1 + 1]) + n0[i2 + 1]);
    const sz = f(f(n0[i0 + 2] + n0[i1 + 2]) + n0[i2 + 2]);
    for (const i of [i0, i1, i2]) {
      sum[i] += sx;
      sum[i + 1] += sy;
      sum[i + 2] += sz;
    }
  }
  for (let v = 0; v < nv * 3; v += 3) {
    const x = sum[v], y = sum[v + 1], z = sum[v + 2];
    const len = f(Math.sqrt(f(f(f(x * x) + f(y * y)) + f(z * z))));
    if (len > 0) {
      sum[v] = x / len;
      sum[v + 1] = y / len;
      sum[v + 2] = z / len;
    } else {
      sum[v] = 0;
      sum[v + 1] = 0;
      sum[v + 2] = 1;
    }
  }
  return sum;
}

function octDecode(u, v, out, o) {
  const f = Math.fround;
  let x = u, y = v;
  const z = f(f(1 - Math.abs(u)) - Math.abs(v));
  if (z < 0) {
    x = f(1 - Math.abs(v)) * (u >= 0 ? 1 : -1);
    y = f(1 - Math.abs(u)) * (v >= 0 ? 1 : -1);
  }
  const len = f(Math.sqrt(f(f(f(x * x) + f(y * y)) + f(z * z))));
  out[o] = x / len;
  out[o + 1] = y / len;
  out[o + 2] = z / len;
}

function decodeG1(r, flags, nv, nt) {
  const normals = (flags & HAS_NORMALS) !== 0, colors = (flags & HAS_COLORS) !== 0;
  const recompute = (flags & RECOMPUTE_NORMALS) !== 0;
  if (normals && recompute) fail('geometry.flags: normals both sent and recomputed');
  if ((flags & COLORS_BY_MEAN) && !colors) fail('geometry.flags: colour prediction flagged without colours');
  const origin = [r.f32('g1.origin'), r.f32('g1.origin'), r.f32('g1.origin')];
  const step = r.f32('g1.step');
  const chromaShift = r.u8('g1.chroma_shift');
  if (chromaShift > 3 || (chromaShift && !colors)) fail('g1.chroma_shift: must be 0..3, and 0 without colours');
  if (!(step >= Math.fround(1e-5) && step <= Math.fround(0.1))) fail('g1.step: must be in [1e-5, 0.1] m');
  for (const o of origin) if (Math.abs(o) > 1e6) fail('g1.origin: not a finite coordinate');
  if (nv > nt * 3) fail(`g1.num_vertices: ${nv} vertices cannot all be referenced by ${nt} triangles`);
  const connB = r.blob32('g1.connectivity');
  const posB = r.blob32('g1.positions');
  const nrmB = normals ? r.blob32('g1.normals') : null;
  const colB = colors ? r.blob32('g1.colors') : null;
  r.expectEnd('g1');

  const conn = new TokenReader(connB, CONN_CONTEXTS, 'g1.connectivity');
  if (nt > 0 && nt > conn.maxSymbols()) {
    fail(`g1.num_triangles: ${nt} triangles cannot fit in ${connB.length} bytes`);
  }
  const pos = new TokenReader(posB, 3, 'g1.positions');
  if (nv * 3 > pos.maxSymbols()) fail(`g1.num_vertices: ${nv} vertices cannot fit in ${posB.length} bytes`);
  const preds = decodeConnectivity(conn, nv, nt);
  const q = new Int32Array(nv * 3);
  decodeResiduals(pos, preds, 3, 65536, true, q);
  let rgb = null;
  if (colors) {
    const tr = new TokenReader(colB, 3, 'g1.colors');
    const ycc = new Int32Array(nv * 3);
    decodeResiduals(tr, preds, 3, 512, !(flags & COLORS_BY_MEAN), ycc);
    rgb = new Uint8Array(nv * 3);
    const s = chromaShift;
    for (let v = 0; v < nv; ++v) {
      const y = ycc[3 * v], co = (ycc[3 * v + 1] << s) - 255, cg = (ycc[3 * v + 2] << s) - 255;
      const t = y - (cg >> 1), g = cg + t, b = t - (co >> 1), rr = b + co;
      rgb[3 * v] = clamp255(rr);
      rgb[3 * v + 1] = clamp255(g);
      rgb[3 * v + 2] = clamp255(b);
    }
  }
  const positions = new Float32Array(nv * 3);
  for (let v = 0; v < nv; ++v)
    for (let c = 0; c < 3; ++c) positions[3 * v + c] = origin[c] + Math.fround(q[3 * v + c] * step);
  let nrm = null;
  if (normals) {
    const tr = new TokenReader(nrmB, 2, 'g1.normals');
    const oct = new Int32Array(nv * 2);
    decodeResiduals(tr, preds, 2, 256, false, oct);
    nrm = new Float32Array(nv * 3);
    const f = Math.fround;
    for (let v = 0; v < nv; ++v) {
      octDecode(f(f(f(oct[2 * v] / 255) * 2) - 1), f(f(f(oct[2 * v + 1] / 255) * 2) - 1), nrm, 3 * v);
    }
  }
  const indices = preds.tris;
  if (recompute) nrm = recomputeNormals(positions, indices, nv);
  return { positions, normals: nrm, colors: rgb, indices };
}

function halfToFloat(h) {
  const s = h & 0x8000 ? -1 : 1, e = (h >> 10) & 0x1f, m = h & 0x3ff;
  if (e === 0) return s * m * 2 ** -24;
  if (e === 31) return m ? NaN : s * Infinity;
  return s * (1 + m / 1024) * 2 ** (e - 15);
}

function decodeG0(r, flags, nv, nt) {
  const normals = (flags & HAS_NORMALS) !== 0, colors = (flags & HAS_COLORS) !== 0;
  const per = 6 + (normals ? 6 : 0) + (colors ? 3 : 0);
  if (nv > r.remaining() / per) fail(`g0.num_vertices: ${nv} vertices exceed the payload`);
  const positions = new Float32Array(nv * 3);
  for (let i = 0; i < nv * 3; ++i) {
    positions[i] = halfToFloat(r.u16('g0.positions'));
    if (!Number.isFinite(positions[i])) fail('g0.positions: not a finite number');
  }
  let nrm = null;
  if (normals) {
    nrm = new Float32Array(nv * 3);
    for (let i = 0; i < nv * 3; ++i) {
      nrm[i] = halfToFloat(r.u16('g0.normals'));
      if (!Number.isFinite(nrm[i])) fail('g0.normals: not a finite number');
    }
  }
  const rgb = colors ? r.bytesView(nv * 3, 'g0.colors').slice() : null;
  const lz = r.blob32('g0.indices');
  r.expectEnd('g0');
  if (nt * 12 > lz.length * 255 + 16) fail(`g0.num_triangles: ${nt} triangles cannot fit in ${lz.length} LZ4 bytes`);
  let indices = new Uint32Array(nt * 3);
  if (nt > 0) {
    const raw = lz4DecodeBlock(lz, nt * 12, 'g0.indices');
    const dv = new DataView(raw.buffer);
    for (let i = 0; i < nt * 3; ++i) {
      indices[i] = dv.getUint32(4 * i, true);
      if (indices[i] >= nv) fail(`g0.indices: vertex index ${indices[i]} out of range (${nv} vertices)`);
    }
  } else if (lz.length) {
    fail('g0.indices: index bytes present for zero triangles');
  }
  return { positions, normals: nrm, colors: rgb, indices };
}

// ---------------------------------------------------------------- G3

const G3_MAX_AXIS = 4096, G3_MAX_SAMPLES = 1 << 24, G3_MAX_OCCUPIED_BRICKS = 65536;
const BRICK_SAMPLES = 64, BRICK_CONTEXTS = 8, LABEL_CONTEXTS = 81, CROSSING_CONTEXTS = 16;
const INSIDE = 2;
const LABEL_SIGN = new Int8Array([0, 1, -1, 0]);

// The labelled part of the grid (PROTOCOL.md §7.2), as the C++ Field: labels
// dense with a margin of two samples on every side (neighbourhoods need no
// bounds checks), crossings per occupied brick, sample × 3 + axis.
class SurfaceField {
  constructor(nx, ny, nz) {
    this.nx = nx;
    this.ny = ny;
    this.nz = nz;
    this.bx = (nx + 3) >> 2;
    this.by = (ny + 3) >> 2;
    this.bz = (nz + 3) >> 2;
    this.brickSlot = new Int32Array(this.bx * this.by * this.bz).fill(-1);
    this.px = nx + 4;
    this.pxy = this.px * (ny + 4);
    this.lab = new Uint8Array(this.pxy * (nz + 4));
    this.slots = 0;
  }
  brick(ix, iy, iz) {
    return ix + this.bx * (iy + this.by * iz);
  }
  brickContext(ix, iy, iz) {
    const s = this.brickSlot;
    return (ix > 0 && s[this.brick(ix - 1, iy, iz)] !== -1 ? 1 : 0) +
      (iy > 0 && s[this.brick(ix, iy - 1, iz)] !== -1 ? 2 : 0) +
      (iz > 0 && s[this.brick(ix, iy, iz - 1)] !== -1 ? 4 : 0);
  }
  // Slots in the order of `bricks` (raster order), then the per-slot arrays.
  addSlots(bricks) {
    for (const b of bricks) this.brickSlot[b] = this.slots++;
    const n = this.slots * BRICK_SAMPLES * 3;
    this.cross = new Int16Array(n);
    this.levels = new Uint8Array(n);
    this.vid = new Uint32Array(n);  // vertex id + 1; 0 = none yet
  }
  // Position of (x, y, z) in `lab`; x, y, z within [−2, n + 1].
  p(x, y, z) {
    return x + 2 + this.px * (y + 2) + this.pxy * (z + 2);
  }
  // Index into `cross` / 3 of a sample in an occupied brick.
  at(x, y, z) {
    return this.brickSlot[(x >> 2) + this.bx * ((y >> 2) + this.by * (z >> 2))] * BRICK_SAMPLES +
      (x & 3) + 4 * ((y & 3) + 4 * (z & 3));
  }
  // fn(x, y, z, p) for every sample of an occupied brick, in raster order
  // over the whole grid (x fastest); p is its position in `lab`. Stops when
  // fn returns true.
  forEachSample(fn) {
    const { nx, ny, nz, bx, by, brickSlot } = this;
    for (let z = 0; z < nz; ++z) {
      for (let y = 0; y < ny; ++y) {
        const row = bx * ((y >> 2) + by * (z >> 2));
        const p0 = this.p(0, y, z);
        for (let b = 0; b < bx; ++b) {
          if (brickSlot[row + b] < 0) continue;
          const x1 = Math.min(nx, 4 * b + 4);
          for (let x = 4 * b; x < x1; ++x) if (fn(x, y, z, p0 + x)) return;
        }
      }
    }
  }
}

// Levels of the crossing on the edge from (x, y, z) along `axis`
// (PROTOCOL.md §7.2 "Crossings"): the surface's normal estimated from the
// labels of the 4×3×3 box around the edge, in doubled integer coordinates.
function edgeLevels(f, x, y, z, axis, levelOf) {
  const lab = f.lab;
  const hx = x + 1 + (axis === 0 ? 1 : 0), hy = y + 1 + (axis === 1 ? 1 : 0), hz = z + 1 + (axis === 2 ? 1 : 0);
  const mx = 2 * x + (axis === 0 ? 1 : 0), my = 2 * y + (axis === 1 ? 1 : 0), mz = 2 * z + (axis === 2 ? 1 : 0);
  let g0 = 0, g1 = 0, g2 = 0;
  for (let qz = z - 1; qz <= hz; ++qz) {
    for (let qy = y - 1; qy <= hy; ++qy) {
      const row = f.p(0, qy, qz);
      let sum = 0, sumX = 0;
      for (let qx = x - 1; qx <= hx; ++qx) {
        const sg = LABEL_SIGN[lab[row + qx] & 3];
        sum += sg;
        sumX += sg * (2 * qx - mx);
      }
      g0 += sumX;
      g1 += sum * (2 * qy - my);
      g2 += sum * (2 * qz - mz);
    }
  }
  const norm2 = g0 * g0 + g1 * g1 + g2 * g2;
  const ga = axis === 0 ? g0 : axis === 1 ? g1 : g2;
  // Small integers (|g| < 200): the double quotient floors exactly.
  return levelOf[norm2 > 0 ? Math.floor((64 * ga * ga) / norm2) : 64];
}

function decodeG3(r, nv, nt) {
  const origin = [r.f32('g3.origin'), r.f32('g3.origin'), r.f32('g3.origin')];
  const voxel = r.f32('g3.voxel');
  const levels = r.u8('g3.levels');
  const nx = r.u16('g3.nx') + 1, ny = r.u16('g3.ny') + 1, nz = r.u16('g3.nz') + 1;
  for (const o of origin) if (Math.abs(o) > 1e6) fail('g3.origin: not a finite coordinate');
  if (!(voxel >= Math.fround(1e-4) && voxel <= 1)) fail('g3.voxel: must be in [1e-4, 1] m');
  if (levels < 2) fail('g3.levels: must be in [2, 255]');
  if (nx > G3_MAX_AXIS || ny > G3_MAX_AXIS || nz > G3_MAX_AXIS) {
    fail(`g3.nx/ny/nz: an axis exceeds ${G3_MAX_AXIS} samples`);
  }
  if ((nx + 4) * (ny + 4) * (nz + 4) > G3_MAX_SAMPLES) {
    fail(`g3.nx/ny/nz: the grid is too large ((nx+4)(ny+4)(nz+4) must be ≤ ${G3_MAX_SAMPLES})`);
  }
  const bricksB = r.blob32('g3.bricks');
  const labelsB = r.blob32('g3.labels');
  const crossingsB = r.blob32('g3.crossings');
  r.expectEnd('g3');
  if (nv > nt * 3) fail(`g3.num_vertices: ${nv} vertices cannot all be referenced by ${nt} triangles`);

  const br = new TokenReader(bricksB, BRICK_CONTEXTS, 'g3.bricks');
  // Every brick costs a symbol: checked before anything is allocated.
  const numBricks = ((nx + 3) >> 2) * ((ny + 3) >> 2) * ((nz + 3) >> 2);
  if (numBricks > br.maxSymbols()) fail(`g3.bricks: ${numBricks} bricks cannot fit in ${bricksB.length} bytes`);
  const f = new SurfaceField(nx, ny, nz);
  const occupied = [];
  for (let z = 0; z < f.bz; ++z) {
    for (let y = 0; y < f.by; ++y) {
      for (let x = 0; x < f.bx; ++x) {
        const bit = br.get(f.brickContext(x, y, z));
        if (!br.ok) fail('g3.bricks: coded data is truncated or corrupt');
        if (bit > 1) fail(`g3.bricks: brick flag ${bit} is not 0 or 1`);
        if (!bit) continue;
        if (occupied.length >= G3_MAX_OCCUPIED_BRICKS) {
          fail(`g3.bricks: more than ${G3_MAX_OCCUPIED_BRICKS} occupied bricks`);
        }
        const b = f.brick(x, y, z);
        f.brickSlot[b] = -2;  // occupied; its slot is given once the count is checked
        occupied.push(b);
      }
    }
  }
  br.finish();

  const lr = new TokenReader(labelsB, LABEL_CONTEXTS, 'g3.labels');
  // Every sample of an occupied brick costs a label symbol.
  if (occupied.length > Math.floor(lr.maxSymbols() / BRICK_SAMPLES) + 1) {
    fail(`g3.bricks: ${occupied.length} occupied bricks cannot fit in ${labelsB.length} bytes of labels`);
  }
  f.addSlots(occupied);
  const lab = f.lab, px = f.px, pxy = f.pxy;
  let badLabel = false;
  f.forEachSample((x, y, z, p) => {
    const l = lr.get(lab[p - 1] + 3 * lab[p - px] + 9 * lab[p - pxy] + 27 * lab[p + 1 - px]);
    if (l > INSIDE) badLabel = true;
    lab[p] = l > INSIDE ? INSIDE : l;
    return !lr.ok;
  });
  if (!lr.ok) fail('g3.labels: coded data is truncated or corrupt');
  if (badLabel) fail('g3.labels: a label is not 0, 1 or 2');
  lr.finish();

  const cr = new TokenReader(crossingsB, CROSSING_CONTEXTS, 'g3.crossings');
  const levelOf = new Uint8Array(65);
  for (let c = 0; c <= 64; ++c) levelOf[c] = Math.max(1, Math.round(levels * Math.sqrt(c / 64)));
  const step = [1, px, pxy];
  let badCrossing = false, crossed = 0;
  f.forEachSample((x, y, z, p) => {
    const l = lab[p];
    if (!l) return false;
    const e0 = 3 * f.at(x, y, z);
    for (let axis = 0; axis < 3; ++axis) {
      const other = lab[p + step[axis]];
      if (!other || other === l) continue;
      const le = edgeLevels(f, x, y, z, axis, levelOf);
      const k = le > 1 ? cr.getValue(Math.min(le, CROSSING_CONTEXTS) - 1) : 0;
      if (!cr.ok) return true;
      if (k >= le) badCrossing = true;
      f.cross[e0 + axis] = k < le ? k : 0;
      f.levels[e0 + axis] = le;
      ++crossed;
    }
    return false;
  });
  if (!cr.ok) fail('g3.crossings: coded data is truncated or corrupt');
  if (badCrossing) fail('g3.crossings: a crossing is outside its edge');
  cr.finish();
  return surfaceMesh(f, origin, voxel, nv, nt, crossed);
}

// Marching cubes over the cubes whose eight corners are labelled, vertices
// numbered in order of first use (one per crossed edge), positions in
// float32 steps as the C++ computes them. `crossed` (the crossed edges)
// bounds what is allocated: a vertex per crossed edge, and at most 12
// triangles in each of the ≤ 4 cubes around one (hostile counts in the
// prefix cost nothing until the labels and crossings bear them out).
function surfaceMesh(f, origin, voxel, nv, nt, crossed) {
  const fr = Math.fround;
  const maxV = Math.min(nv, crossed), maxT = Math.min(nt, 48 * crossed);
  const positions = new Float32Array(3 * maxV), indices = new Uint32Array(3 * maxT);
  const { lab, vid, cross, levels } = f;
  let numV = 0, numT = 0, overflow = false;
  const vertex = (x, y, z, axis) => {
    const e = 3 * f.at(x, y, z) + axis;
    if (vid[e]) return vid[e] - 1;
    if (numV >= maxV) {
      overflow = true;
      return 0;
    }
    const t = fr(fr(cross[e] + 0.5) / levels[e]);
    const o = 3 * numV;
    positions[o] = origin[0] + fr(voxel * (axis === 0 ? fr(x + t) : x));
    positions[o + 1] = origin[1] + fr(voxel * (axis === 1 ? fr(y + t) : y));
    positions[o + 2] = origin[2] + fr(voxel * (axis === 2 ? fr(z + t) : z));
    vid[e] = numV + 1;
    return numV++;
  };
  const cases = mcCases();
  const corner = new Int32Array(8);
  for (let c = 0; c < 8; ++c) corner[c] = (c & 1) + f.px * ((c >> 1) & 1) + f.pxy * ((c >> 2) & 1);
  f.forEachSample((x, y, z, p) => {
    if (!lab[p]) return false;
    let code = 0;
    for (let c = 0; c < 8; ++c) {
      const l = lab[p + corner[c]];
      if (!l) return false;
      if (l === INSIDE) code |= 1 << c;
    }
    if (code === 0 || code === 255) return false;
    const edges = cases[code];
    for (let k = 0; k < edges.length; k += 3) {
      if (numT >= maxT) overflow = true;
      for (let j = 0; j < 3 && !overflow; ++j) {
        const e = edges[k + j], c = EDGE_LOW[e];
        indices[3 * numT + j] = vertex(x + (c & 1), y + ((c >> 1) & 1), z + ((c >> 2) & 1), EDGE_AXIS[e]);
      }
      if (overflow) return true;
      ++numT;
    }
    return false;
  });
  if (overflow) fail('g3: the surface has more vertices or triangles than the prefix says');
  if (numV !== nv || numT !== nt) {
    fail(`g3: the surface has ${numV} vertices and ${numT} triangles, the prefix says ${nv} and ${nt}`);
  }
  return { positions, normals: recomputeNormals(positions, indices, nv), colors: null, indices };
}

// Decodes a geometry blob (Uint8Array).
export function decodeGeometry(blob, limits = LIMITS) {
  const r = new Reader(blob);
  const codec = r.u8('geometry.codec');
  const flags = r.u8('geometry.flags');
  const reserved = r.u16('geometry.reserved');
  const nv = r.u32('geometry.num_vertices');
  const nt = r.u32('geometry.num_triangles');
  if (flags & ~(HAS_NORMALS | HAS_COLORS | RECOMPUTE_NORMALS | COLORS_BY_MEAN)) fail('geometry.flags: unknown flag bits set');
  if (codec !== 2 && flags & (RECOMPUTE_NORMALS | COLORS_BY_MEAN)) fail('geometry.flags: bits 2-3 are G1 only');
  if (reserved !== 0) fail('geometry.reserved: must be zero');
  if (nv > limits.maxVertices) fail(`geometry.num_vertices: ${nv} exceeds limit ${limits.maxVertices}`);
  if (nt > limits.maxTriangles) fail(`geometry.num_triangles: ${nt} exceeds limit ${limits.maxTriangles}`);
  if (codec === 1) return decodeG0(r, flags, nv, nt);
  if (codec === 2) return decodeG1(r, flags, nv, nt);
  if (codec === 4) {
    if (flags !== 0) fail('geometry.flags: must be 0 for G3');
    return decodeG3(r, nv, nt);
  }
  return fail(`geometry.codec: unknown geometry codec ${codec}`);
}
