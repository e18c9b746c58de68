// Bounds-checked little-endian reading of untrusted bytes. Every failure is a
// DecodeError whose message names the field (as the C++ decoders do).

export class DecodeError extends Error {
  constructor(message) {
    super(message);
    this.name = 'DecodeError';
  }
}

export function fail(message) {
  throw new DecodeError(message);
}

export class Reader {
  // `bytes`: a Uint8Array (a view; never copied).
  constructor(bytes, offset = 0, end = bytes.length) {
    this.bytes = bytes;
    this.view = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
    this.pos = offset;
    this.end = end;
  }
  remaining() {
    return this.end - this.pos;
  }
  need(n, field) {
    if (n > this.end - this.pos) fail(`${field}: truncated (needs ${n} bytes, ${this.end - this.pos} left)`);
  }
  u8(field) {
    this.need(1, field);
    return this.bytes[this.pos++];
  }
  u16(field) {
    this.need(2, field);
    const v = this.view.getUint16(this.pos, true);
    this.pos += 2;
    return v;
  }
  u32(field) {
    this.need(4, field);
    const v = this.view.getUint32(this.pos, true);
    this.pos += 4;
    return v;
  }
  i32(field) {
    this.need(4, field);
    const v = this.view.getInt32(this.pos, true);
    this.pos += 4;
    return v;
  }
  // 64-bit values as JS numbers (exact up to 2^53; larger values are refused).
  i64(field) {
    this.need(8, field);
    const v = this.view.getBigInt64(this.pos, true);
    this.pos += 8;
    if (v > BigInt(Number.MAX_SAFE_INTEGER) || v < -BigInt(Number.MAX_SAFE_INTEGER)) fail(`${field}: out of range`);
    return Number(v);
  }
  u64(field) {
    this.need(8, field);
    const v = this.view.getBigUint64(this.pos, true);
    this.pos += 8;
    if (v > BigInt(Number.MAX_SAFE_INTEGER)) fail(`${field}: out of range`);
    return Number(v);
  }
  f32(field) {
    this.need(4, field);
    const v = this.view.getFloat32(this.pos, true);
    this.pos += 4;
    if (!Number.isFinite(v)) fail(`${field}: not a finite number`);
    return v;
  }
  f64(field) {
    this.need(8, field);
    const v = this.view.getFloat64(this.pos, true);
    this.pos += 8;
    if (!Number.isFinite(v)) fail(`${field}: not a finite number`);
    return v;
  }
  bytesView(n, field) {
    this.need(n, field);
    const v = this.bytes.subarray(this.pos, this.pos + n);
    this.pos += n;
    return v;
  }
  blob32(field) {
    const n = this.u32(field);
    return this.bytesView(n, field);
  }
  str16(field, max = 1024) {
    const n = this.u16(field);
    if (n > max) fail(`${field}: ${n} bytes exceed the limit of ${max}`);
    return new TextDecoder().decode(this.bytesView(n, field));
  }
  expectEnd(field) {
    if (this.pos !== this.end) fail(`${field}: ${this.end - this.pos} trailing bytes`);
  }
}

// CRC-32C (Castagnoli), as the recording container uses.
const CRC32C_TABLE = (() => {
  const t = new Uint32Array(256);
  for (let i = 0; i < 256; ++i) {
    let c = i;
    for (let k = 0; k < 8; ++k) c = c & 1 ? (c >>> 1) ^ 0x82f63b78 : c >>> 1;
    t[i] = c >>> 0;
  }
  return t;
})();

export function crc32c(bytes, crc = 0) {
  let c = ~crc >>> 0;
  for (let i = 0; i < bytes.length; ++i) c = CRC32C_TABLE[(c ^ bytes[i]) & 0xff] ^ (c >>> 8);
  return ~c >>> 0;
}

// LZ4 block format decoder into a buffer of exactly `size` bytes.
export function lz4DecodeBlock(src, size, field) {
  const out = new Uint8Array(size);
  let ip = 0;
  let op = 0;
  const n = src.length;
  while (ip < n) {
    const token = src[ip++];
    let lit = token >>> 4;
    if (lit === 15) {
      let b;
      do {
        if (ip >= n) fail(`${field}: LZ4 literal length truncated`);
        b = src[ip++];
        lit += b;
      } while (b === 255);
    }
    if (lit > n - ip || lit > size - op) fail(`${field}: LZ4 literals out of range`);
    out.set(src.subarray(ip, ip + lit), op);
    ip += lit;
    op += lit;
    if (ip === n) break;  // the last sequence has literals only
    if (n - ip < 2) fail(`${field}: LZ4 offset truncated`);
    const offset = src[ip] | (src[ip + 1] << 8);
    ip += 2;
    if (offset === 0 || offset > op) fail(`${field}: LZ4 offset out of range`);
    let len = (token & 15) + 4;
    if ((token & 15) === 15) {
      let b;
      do {
        if (ip >= n) fail(`${field}: LZ4 match length truncated`);
        b = src[ip++];
        len += b;
      } while (b === 255);
    }
    if (len > size - op) fail(`${field}: LZ4 match overruns the output`);
    for (let k = 0; k < len; ++k, ++op) out[op] = out[op - offset];
  }
  if (op !== size) fail(`${field}: LZ4 data decodes to ${op} bytes, expected ${size}`);
  return out;
}
