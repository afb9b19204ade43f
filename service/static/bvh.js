// BVH motion values and forward kinematics in the browser, for drawing a file's frames.
//
// The hierarchy is not parsed here: the service reads it (POST v1/bvh/inspect answers each
// joint's name, parent, offset, channels and first MOTION column, End Sites included, in
// file order), so the page and the service agree on every joint. Conventions as
// core/bvh.py: Euler channels are intrinsic rotations in the listed order, in degrees
// (R = R_c1 @ R_c2 @ R_c3); position channels replace the matching OFFSET component;
// world G[j] = G[parent] @ R[j], P[j] = P[parent] + G[parent] @ t[j].

const MOTION_RE = /^[ \t]*MOTION[ \t]*\r?$/m;
const POSITION = { xposition: 0, yposition: 1, zposition: 2 };
const ROTATION = { xrotation: 'X', yrotation: 'Y', zrotation: 'Z' };
const DEG = Math.PI / 180;

// The MOTION header's lines: where the "Frames:" line stands ([start, end), its line end
// left out) and where the frame lines start (``at``: after the MOTION line, "Frames:" and
// "Frame Time:").
export function motionHeader(text) {
  const m = MOTION_RE.exec(text);
  if (!m) throw new Error('not a BVH file: no MOTION line');
  const ends = [];
  let i = m.index + m[0].length;
  for (let k = 0; k < 3; k += 1) {
    // the rest of the MOTION line, then "Frames:" and "Frame Time:"
    i = text.indexOf('\n', i);
    if (i < 0) throw new Error('truncated MOTION header');
    ends.push(i);
    i += 1;
  }
  return { frames: [ends[0] + 1, ends[1]], at: i };
}

const motionStart = (text) => motionHeader(text).at;

// The MOTION values a frame holds: every channel of the inspect answer's joints.
export const channelCount = (info) => info.joints.reduce((n, j) => n + j.channels.length, 0);

// Every MOTION value of the file, frame after frame (Float64Array), each word read as the
// service reads it (``bvhValue``: NaN for one it refuses). A file whose frames are not one a
// line (wrapped over lines) is read so: its words were read by JavaScript's Number, which
// reads 0x10 as 16, so such a frame was drawn, and its drag got the service's 422.
export function parseMotion(text) {
  const found = words(text.slice(motionStart(text)));
  const out = new Float64Array(found.length);
  for (let i = 0; i < found.length; i += 1) out[i] = bvhValue(found[i]); // (Float64Array.from: 3x)
  return out;
}

// The values of one frame (Float64Array of ``channels``) read from its line alone (a 1 MB
// file: ~0.5 ms, not parseMotion's 12-30 ms); null unless the file holds one frame per
// line, ``frames`` lines less the blank ones (the service's rule for splicing a frame).
export function frameValues(text, frame, frames, channels) {
  const line = frameLine(text, frame, frames);
  return line && lineValues(text.slice(line[0], line[1]), channels);
}

// Where the line of ``frame`` stands ([start, end), its LF left out), or null unless the file
// holds one frame per line, ``frames`` lines less the blank ones (``frameValues``).
export function frameLine(text, frame, frames) {
  const blank = new RegExp(`(?:(?!\\n)[${SPACE}])*(?:\\n|$)`, 'y');
  let pos = motionStart(text);
  let seen = 0;
  let line = null;
  while (pos <= text.length) {
    let end = text.indexOf('\n', pos);
    if (end < 0) end = text.length;
    blank.lastIndex = pos;
    if (!blank.test(text)) {
      if (seen === frame) line = [pos, end];
      seen += 1;
    }
    pos = end + 1;
  }
  return seen === frames ? line : null;
}

// The white space the service's reader splits words at (Python's str.split()): JavaScript's
// \s leaves out \x1c-\x1f and \x85 and takes U+FEFF. A frame whose values were parted by
// \x1f was read by the service and drawn by the page as no pose, its view set up from NaN.
export const SPACE = '\\t-\\r\\x1c-\\x20\\x85\\xa0\\u1680\\u2000-\\u200a\\u2028\\u2029\\u202f\\u205f\\u3000';
const WORD_RE = new RegExp(`[^${SPACE}]+`, 'g');
// The words of ``text``, as the service's reader parts them.
export const words = (text) => text.match(WORD_RE) || [];

// A number as the service's reader reads one (core/bvh_words.py NUMBER): ASCII decimals, a
// sign, a point, an exponent. JavaScript's Number also reads 0x10, 0b11, 0o7 and Infinity,
// which the service refuses: such a frame was drawn, and its drag got the service's 422.
export const NUMBER_RE = /^[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?$/;
export const bvhNumber = (word) => (NUMBER_RE.test(word) ? Number(word) : NaN);
// The most a channel value may be (service/characters.py MAX_COORDINATE): the service refuses
// to edit a frame holding one past it, so such a frame is read as broken (NaN), as 0x10 is.
export const MAX_VALUE = 1.0e7;
// (Number first, the regex only for a word Number may read and NUMBER not: a radix prefix,
// 0x 0o 0b, or the white space Number trims and a word may hold, U+FEFF; a fuzz of 3 M
// words agrees with NUMBER first. NUMBER on each word made a 7.5 MB file read whole, for
// frames wrapped over lines, 50% slower.)
export const bvhValue = (word) => {
  const v = Number(word);
  if (!(Math.abs(v) <= MAX_VALUE)) return NaN;
  const c = word.charCodeAt(1) | 0x20;
  if (c === 0x78 || c === 0x6f || c === 0x62 || word.includes('\ufeff')) return bvhNumber(word);
  return v;
};

// The values of one frame's line (Float64Array of ``channels``; NaN for a word that is no
// number within the bound, ``bvhValue``), or null where it holds another number of values: how
// ``frameValues`` reads the frame's line once it has found it (a spliced answer's line is
// read so: editor/excerpt.js).
export function lineValues(line, channels) {
  const tokens = words(line);
  return tokens.length === channels ? Float64Array.from(tokens, bvhValue) : null;
}

// 3x3 matrices as row-major arrays of 9.
function mul(a, b) {
  const o = new Array(9);
  for (let r = 0; r < 3; r += 1) {
    for (let c = 0; c < 3; c += 1) {
      o[3 * r + c] = a[3 * r] * b[c] + a[3 * r + 1] * b[3 + c] + a[3 * r + 2] * b[6 + c];
    }
  }
  return o;
}

function apply(m, v) {
  return [
    m[0] * v[0] + m[1] * v[1] + m[2] * v[2],
    m[3] * v[0] + m[4] * v[1] + m[5] * v[2],
    m[6] * v[0] + m[7] * v[1] + m[8] * v[2],
  ];
}

function axisRotation(axis, radians) {
  const c = Math.cos(radians);
  const s = Math.sin(radians);
  if (axis === 'X') return [1, 0, 0, 0, c, -s, 0, s, c];
  if (axis === 'Y') return [c, 0, s, 0, 1, 0, -s, 0, c];
  return [c, -s, 0, s, c, 0, 0, 0, 1];
}

const IDENTITY = [1, 0, 0, 0, 1, 0, 0, 0, 1];

// World rotations and positions (file units and axes) of every joint for one MOTION row;
// ``rootAdd``: a root's position channels are a displacement from its OFFSET (the
// service's ``root_position: "add"``), not its position.
export function forwardKinematics(joints, row, rootAdd = false) {
  const rot = new Array(joints.length);
  const pos = new Array(joints.length);
  joints.forEach((j, i) => {
    let r = IDENTITY;
    const t = [...j.offset];
    j.channels.forEach((name, k) => {
      const key = name.toLowerCase();
      const v = row[j.channel_start + k];
      if (key in POSITION) t[POSITION[key]] = v + (rootAdd && j.parent < 0 ? j.offset[POSITION[key]] : 0);
      else r = mul(r, axisRotation(ROTATION[key], v * DEG));
    });
    if (j.parent < 0) {
      rot[i] = r;
      pos[i] = t;
    } else {
      const g = rot[j.parent];
      const p = pos[j.parent];
      const d = apply(g, t);
      rot[i] = mul(g, r);
      pos[i] = [p[0] + d[0], p[1] + d[1], p[2] + d[2]];
    }
  });
  return { rot, pos };
}

// The canonical points: each anchor is fixed in one joint's frame.
export function anchorPoints(joints, anchors, fk) {
  const index = new Map(joints.map((j, i) => [j.name, i]));
  const out = {};
  for (const [canonical, a] of Object.entries(anchors)) {
    const i = index.get(a.joint);
    const d = apply(fk.rot[i], a.offset);
    const p = fk.pos[i];
    out[canonical] = [p[0] + d[0], p[1] + d[1], p[2] + d[2]];
  }
  return out;
}
