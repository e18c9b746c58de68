// Colour codecs of ColorFrame images (PROTOCOL.md §8): C0 and C1, a port of
// protocol/color_codec.cc's decoders. The JPEG inside C1 is decoded by a
// function the caller gives (the browser's own decoder in the page; a JS
// decoder in node tests): `decodeJpeg(bytes) → Promise<{width, height, data}>`
// with `data` RGBA8, rows top to bottom. Safe on untrusted input: malformed
// data throws a DecodeError naming the field.
//
// The result: { width, height, rgba: Uint8Array (background pixels 0, alpha =
// the mask: 255 foreground, 0 background), box: {x, y, w, h} }.

import { decompress as zstdDecompress } from 'fzstd';
import { Reader, fail, lz4DecodeBlock } from './bytes.js';

export const LIMITS = { maxImageDim: 8192, maxImagePixels: 8 << 20 };

function checkSize(field, w, h, limits) {
  if (w < 1 || h < 1 || w > limits.maxImageDim || h > limits.maxImageDim || w * h > limits.maxImagePixels) {
    fail(`${field}: image size ${w}x${h} outside 1..${limits.maxImageDim}, at most ${limits.maxImagePixels} pixels`);
  }
}

export function getVarint(buf, st) {
  let r = 0;
  for (let shift = 0; shift <= 28; shift += 7) {
    if (st.p >= buf.length) return -1;
    const b = buf[st.p++];
    if (shift === 28 && b & 0x70) return -1;
    r += (b & 0x7f) * 2 ** shift;
    if (!(b & 0x80)) return r;
  }
  return -1;
}

// Size and MCU of a baseline/progressive JPEG from its SOF marker.
export function jpegInfo(jpeg) {
  let p = 2;
  if (jpeg.length < 4 || jpeg[0] !== 0xff || jpeg[1] !== 0xd8) fail('c1.jpeg: not a JPEG image');
  while (p + 4 <= jpeg.length) {
    if (jpeg[p] !== 0xff) fail('c1.jpeg: not a JPEG image');
    const m = jpeg[p + 1];
    if (m === 0xff) {
      ++p;
      continue;
    }
    const len = (jpeg[p + 2] << 8) | jpeg[p + 3];
    if (m >= 0xc0 && m <= 0xcf && m !== 0xc4 && m !== 0xc8 && m !== 0xcc) {
      if (p + 2 + len > jpeg.length || len < 8) fail('c1.jpeg: not a JPEG image');
      const h = (jpeg[p + 5] << 8) | jpeg[p + 6], w = (jpeg[p + 7] << 8) | jpeg[p + 8], nc = jpeg[p + 9];
      if (nc < 1 || len < 8 + 3 * nc) fail('c1.jpeg: not a JPEG image');
      let hmax = 1, vmax = 1;
      for (let c = 0; c < nc; ++c) {
        const s = jpeg[p + 11 + 3 * c];
        hmax = Math.max(hmax, s >> 4);
        vmax = Math.max(vmax, s & 15);
      }
      if (nc === 1) hmax = vmax = 1;
      return { width: w, height: h, mcuW: 8 * hmax, mcuH: 8 * vmax };
    }
    if (m === 0xd9 || m === 0xda) break;
    p += 2 + len;
  }
  return fail('c1.jpeg: not a JPEG image');
}

async function decodeC1(r, W, H, packed, decodeJpeg) {
  const x0 = r.u16('c1.box_x'), y0 = r.u16('c1.box_y'), bw = r.u16('c1.box_width'), bh = r.u16('c1.box_height');
  const zmask = r.blob32('c1.mask');
  const jpeg = r.blob32('c1.jpeg');
  r.expectEnd('c1');
  const rgba = new Uint8Array(W * H * 4);
  const emptyBox = bw === 0 || bh === 0;
  if (emptyBox) {
    if (bw || bh || x0 || y0 || zmask.length || jpeg.length) {
      fail('c1.box: an empty box must be all zero with no mask or JPEG bytes');
    }
    return { width: W, height: H, rgba, box: { x: 0, y: 0, w: 0, h: 0 } };
  }
  if (x0 + bw > W || y0 + bh > H) fail(`c1.box: box ${x0},${y0} ${bw}x${bh} leaves the ${W}x${H} image`);
  const info = jpegInfo(jpeg);
  const bx = info.mcuW, by = info.mcuH;
  const cols = Math.ceil(bw / bx), rows = Math.ceil(bh / by);
  const slot = new Int32Array(cols * rows);
  const rle = unzstdRows(zmask, bw, bh, 'c1.mask', 'box');
  const st = { p: 0 };
  const transitions = [];
  const rowAt = new Uint32Array(bh + 1);
  for (let y = 0; y < bh; ++y) {
    const head = getVarint(rle, st);
    if (head < 0) fail(`c1.mask: row ${y} ends early`);
    const first = transitions.length;
    if (head === 0) {
      for (let k = y > 0 ? rowAt[y - 1] : 0; k < first; ++k) {
        const z = getVarint(rle, st);
        if (z < 0) fail(`c1.mask: row ${y} ends early`);
        const d = z % 2 ? -(z + 1) / 2 : z / 2;
        transitions.push(transitions[k] + d);
      }
    } else {
      if (head - 1 > bw) fail(`c1.mask: row ${y} has more transitions than pixels`);
      let next = 0;
      for (let i = 0; i + 1 < head; ++i) {
        const gap = getVarint(rle, st);
        if (gap < 0) fail(`c1.mask: row ${y} ends early`);
        if (gap >= bw) fail(`c1.mask: transition outside row ${y}`);
        transitions.push(next + gap);
        next = next + gap + 1;
      }
    }
    for (let i = first; i < transitions.length; ++i) {
      if (transitions[i] < 0 || transitions[i] >= bw || (i > first && transitions[i] <= transitions[i - 1])) {
        fail(`c1.mask: transitions of row ${y} out of order or outside the box`);
      }
    }
    if (packed) {
      const srow = Math.floor(y / by) * cols;
      for (let i = first; i < transitions.length; i += 2) {
        const stop = i + 1 < transitions.length ? transitions[i + 1] : bw;
        for (let c = Math.floor(transitions[i] / bx), last = Math.floor((stop - 1) / bx); c <= last; ++c) slot[srow + c] = 1;
      }
    }
    rowAt[y + 1] = transitions.length;
  }
  if (st.p !== rle.length) fail('c1.mask: trailing run lengths');
  let coded = 0;
  for (let i = 0; i < slot.length; ++i) slot[i] = !packed || slot[i] > 0 ? coded++ : -1;
  if (packed && coded === 0) fail('c1.mask: a packed box must hold foreground');
  const wantW = packed ? cols * bx : bw, wantH = packed ? Math.ceil(coded / cols) * by : bh;
  if (info.width !== wantW || info.height !== wantH) {
    fail(`c1.jpeg: JPEG is ${info.width}x${info.height}, ${packed ? 'the packed blocks need' : 'box is'} ${wantW}x${wantH}`);
  }
  let img;
  try {
    img = await decodeJpeg(jpeg);
  } catch (e) {
    fail(`c1.jpeg: ${e.message || e}`);
  }
  if (img.width !== info.width || img.height !== info.height) fail('c1.jpeg: decoded size differs from its header');
  const src = img.data, jw = img.width;
  for (let y = 0; y < bh; ++y) {
    const r0 = Math.floor(y / by), jy = y - r0 * by;
    const drow = ((y0 + y) * W + x0) * 4;
    for (let i = rowAt[y]; i < rowAt[y + 1]; i += 2) {
      const start = transitions[i], stop = i + 1 < rowAt[y + 1] ? transitions[i + 1] : bw;
      for (let x = start; x < stop; ++x) {
        const c = Math.floor(x / bx);
        const s = slot[r0 * cols + c];
        const sx = (s % cols) * bx + (x - c * bx), sy = Math.floor(s / cols) * by + jy;
        const si = (sy * jw + sx) * 4, di = drow + x * 4;
        rgba[di] = src[si];
        rgba[di + 1] = src[si + 1];
        rgba[di + 2] = src[si + 2];
        rgba[di + 3] = 255;
      }
    }
  }
  return { width: W, height: H, rgba, box: { x: x0, y: y0, w: bw, h: bh } };
}

// The mask rows of a w × h area from a zstd frame that declares its content
// size (checked against the area before anything is allocated).
export function unzstdRows(zmask, w, h, field, area) {
  const declared = zstdContentSize(zmask);
  if (declared < 0 || declared > h * (w + 1) * 3 || declared < h) {
    fail(`${field}: zstd frame size is missing or impossible for the ${area}`);
  }
  let rle;
  try {
    rle = zstdDecompress(zmask, new Uint8Array(declared));
  } catch (e) {
    fail(`${field}: zstd data is corrupt (${e.message})`);
  }
  if (rle.length !== declared) fail(`${field}: zstd data is corrupt`);
  return rle;
}

// Frame_Content_Size of a zstd frame header, or -1 if absent or malformed.
function zstdContentSize(z) {
  if (z.length < 5 || z[0] !== 0x28 || z[1] !== 0xb5 || z[2] !== 0x2f || z[3] !== 0xfd) return -1;
  const fhd = z[4];
  const fcsFlag = fhd >> 6, single = (fhd >> 5) & 1, didFlag = fhd & 3;
  if (fhd & 0x08) return -1;  // reserved bit
  let p = 5 + (single ? 0 : 1) + [0, 1, 2, 4][didFlag];
  const size = [single ? 1 : 0, 2, 4, 8][fcsFlag];
  if (size === 0 || p + size > z.length) return -1;
  let v = 0;
  for (let i = size - 1; i >= 0; --i) v = v * 256 + z[p + i];
  if (size === 2) v += 256;
  return v;
}

function decodeC0(r, W, H) {
  const lz = r.blob32('c0.data');
  r.expectEnd('c0');
  if (W * H * 3 > lz.length * 255 + 16) fail('c0.data: image cannot fit in the LZ4 bytes');
  const rgb = lz4DecodeBlock(lz, W * H * 3, 'c0.data');
  const rgba = new Uint8Array(W * H * 4);
  for (let i = 0, j = 0; i < W * H; ++i, j += 3) {
    const fg = rgb[j] | rgb[j + 1] | rgb[j + 2];
    if (fg) {
      rgba[4 * i] = rgb[j];
      rgba[4 * i + 1] = rgb[j + 1];
      rgba[4 * i + 2] = rgb[j + 2];
      rgba[4 * i + 3] = 255;
    }
  }
  return { width: W, height: H, rgba, box: { x: 0, y: 0, w: W, h: H } };
}

// Decodes a colour blob (Uint8Array).
export async function decodeColor(blob, decodeJpeg, limits = LIMITS) {
  const r = new Reader(blob);
  const codec = r.u8('color.codec');
  const flags = r.u8('color.flags');
  const w = r.u16('color.width'), h = r.u16('color.height');
  checkSize('color', w, h, limits);
  if (codec === 1) {
    if (flags) fail('color.flags: C0 has no flags');
    return decodeC0(r, w, h);
  }
  if (codec === 2) {
    if (flags & ~1) fail('color.flags: unknown flag bits set');
    return decodeC1(r, w, h, (flags & 1) !== 0, decodeJpeg);
  }
  if (codec === 3 || codec === 4) fail(`color.codec: codec ${codec} is not supported by this viewer`);
  return fail(`color.codec: unknown colour codec ${codec}`);
}
