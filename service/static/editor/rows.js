// A BVH file's frames' values, read from its text as the service reads them (static/bvh.js:
// its words, its numbers): one frame's row for drawing it, why a frame has none (a broken
// line, a word the service refuses), and the texts kept to read them from.

import { doc } from './state.js';
import {
  bvhNumber, bvhValue, channelCount, frameLine, frameValues, MAX_VALUE, motionHeader, parseMotion,
  SPACE, words,
} from '../bvh.js';
import { forgetLayout, oneFrameALine } from './excerpt.js';

// text -> MOTION values, of the texts committed and shown only (and the one asked for): a
// file read whole (its frames not one per line) kept its last six texts, each answer of a
// drag one, and their values (a 7.5 MB file: 7.5 MB of text and 6 MB of values each, 50 MB
// of the page's heap after six edits).
const motionCache = new Map();

// A text kept to read frames from: the open file's shown or committed one. (The shown one
// first: the last row's text is it, the same string, known at once; compared with the
// committed one first, a new answer's text as long was compared character by character,
// copied whole first: 3.4 ms an answer on a 7.5 MB file.)
const inUse = (text) => doc.active && (text === doc.shown || text === doc.text);

function cached(text) {
  for (const key of motionCache.keys()) if (!inUse(key) && key !== text) motionCache.delete(key);
  return motionCache.get(text);
}

function motionOf(text) {
  let values = cached(text);
  if (!values) {
    values = parseMotion(text);
    motionCache.set(text, values);
  }
  return values;
}

// One frame's values of a text: a text read whole (motionCache) has them; else its frame's
// line alone is read (each answer of a solve is a new text: reading a 1 MB file whole took
// 12-30 ms per answer), the file whole only when it does not hold one frame per line.
// ``known``: the frame's values as the text's maker has them (an excerpt's answer spliced
// in: editor/excerpt.js), kept as the frame's row without reading the text at all: each
// answer's new text was walked to the frame's line and looked up in motionCache (a Map: the
// lookup hashes the whole text), 8-49 ms an answer on a 7.5 MB file (docs/editor.md).
const NO_ROW = Object.freeze({ text: null, frame: -1, row: null });
let lastRow = NO_ROW;

export function frameRow(text, frame, known) {
  const n = channelCount(doc.info);
  if (known && known.length === n) {
    const row = known.every(Number.isFinite) ? known : new Float64Array(n).fill(NaN);
    lastRow = { text, frame, row };
    return row;
  }
  if (lastRow.text === text && lastRow.frame === frame) return lastRow.row;
  const values = motionCache.size ? cached(text) : undefined; // (none: a file one frame a line)
  if (values) return wordsRow(text, frame, values.subarray(frame * n, (frame + 1) * n));
  let row = frameValues(text, frame, doc.info.frames, n);
  // A frame's line of a file one frame a line (as the server reads it: a file with a blank
  // line among its frames is read as words, whatever a line holds) that holds another count
  // of values, or one that is no number (the service's rows_warning): that frame has no pose (nothing drawn,
  // nothing grabbed; showFrame says why). It was read from the whole file's values, every
  // value after the line's shifted: another pose drawn, a limb lost, without a word.
  if (!row && oneFrameALine(text, doc.info.frames, n)) row = new Float64Array(n).fill(NaN);
  if (!row) return wordsRow(text, frame, motionOf(text).subarray(frame * n, (frame + 1) * n));
  if (!row.every(Number.isFinite)) row = new Float64Array(n).fill(NaN);
  lastRow = { text, frame, row }; // (a row of the whole file's values kept them, and a text no longer shown)
  return row;
}

// A frame's values read from the whole file's words (a file not one frame a line: its frames
// wrapped over lines), kept by motionCache; where one is no number the service reads (a
// word that is none, ``bvhValue``), or the file holds too few, the frame has no pose, as a
// broken line's frame (above): its words were read by JavaScript's Number, 0x10 drawn as
// 16, and its drag got the service's 422.
function wordsRow(text, frame, values) {
  const n = channelCount(doc.info);
  if (values.length === n && values.every(Number.isFinite)) return values; // (not kept: motionCache)
  const row = new Float64Array(n).fill(NaN);
  lastRow = { text, frame, row };
  return row;
}

// The words of frame ``frame`` of ``text`` and where each starts: its line's, where the file
// holds one frame a line; else the frame's ``channels`` words over the block (frames
// wrapped over lines, read as the service reads them: word after word).
function frameWords(text, frame, channels) {
  const found = [];
  const re = new RegExp(`[^${SPACE}]+`, 'g');
  const at = oneFrameALine(text, doc.info.frames, channels) && frameLine(text, frame, doc.info.frames);
  if (at) {
    re.lastIndex = at[0];
    for (let m = re.exec(text); m && m.index < at[1]; m = re.exec(text)) found.push(m);
    return found;
  }
  re.lastIndex = motionHeader(text).at;
  const skip = frame * channels;
  for (let k = 0, m = re.exec(text); m && found.length < channels; k += 1, m = re.exec(text)) {
    if (k >= skip) found.push(m);
  }
  return found;
}

// Why frame ``frame`` of ``text`` has no pose, where its line holds another count of
// values than the file's channels, or it (one frame a line or not) holds a value that is no
// number the service reads; else null.
export function brokenRow(text, frame) {
  const n = channelCount(doc.info);
  const found = frameWords(text, frame, n);
  const bad = found.find((m) => !Number.isFinite(bvhValue(m[0]))); // (as the service reads it)
  if (found.length === n && bad === undefined) return null;
  const at = bad ? bad.index : found.length ? found[0].index : motionHeader(text).at;
  let line = 1; // (of the word refused: a frame over several lines)
  for (let i = text.indexOf('\n'); i >= 0 && i < at; i = text.indexOf('\n', i + 1)) line += 1;
  const word = bad && bad[0];
  const holds = found.length !== n ? `${found.length} values, not ${n}`
    : Number.isFinite(bvhNumber(word)) ? `a value past ±${String(MAX_VALUE.toExponential())
      .replace('+', '')} ('${word.slice(0, 20)}')` : `a value that is no number ('${word.slice(0, 20)}')`;
  return `${doc.name}: line ${line}: frame ${frame} holds ${holds}: it has no pose to draw or `
    + 'edit (the other frames have; Export writes this line as it is)';
}

// One frame's values of a text (the same array while the text and frame are the ones last
// read: scene.js draws the file's own bones anew only when they change).
export const fileRow = (text, frame) => frameRow(text, frame, null);

// The texts kept to read frames from let go of, but those ``inUse``: the texts read
// whole and their values, the last frame's row, the committed text's layout
// (editor/excerpt.js). After each change (refreshFrame), and as a file is opened, read
// again or closed (the texts before of no use). ``all``: every one let go (a file opened
// or read again: its text is a new string, and one kept as the same, though another
// string, would be compared with it whole at each look, a 7.5 MB file's at each excerpt).
export function releaseTexts(all = false) {
  if (all) {
    motionCache.clear();
    lastRow = NO_ROW;
    forgetLayout(null);
    return;
  }
  cached(null);
  if (!inUse(lastRow.text)) lastRow = NO_ROW;
  forgetLayout(doc.active ? doc.text : null);
}


// The first frame of ``text`` the page reads whole (as many values as its CHANNELS lines
// declare, each a number the service reads), before its inspection tells its channels: 0
// for nearly every file (its first line is such a frame), -1 where none is (or it has no
// MOTION header). A file whose frame 0 is broken is inspected at this frame (file.js
// openText): inspected at frame 0, the service refused the whole file for that frame alone,
// and a frame 0 the page could not read (values parted by \x1f, read as one word) set the
// view up from NaN.
export function firstWholeFrame(text) {
  let header;
  try {
    header = motionHeader(text);
  } catch {
    return -1;
  }
  const frames = Number((/^[ \t]*Frames:[ \t]*(\S+)/.exec(text.slice(...header.frames)) || [])[1]);
  const channels = [...text.slice(0, header.at).matchAll(/^[ \t]*CHANNELS[ \t]+(\d+)/gim)]
    .reduce((n, m) => n + Number(m[1]), 0);
  if (!Number.isInteger(frames) || frames < 1 || channels < 1) return -1;
  const whole = (found) => found.length === channels && found.every((w) => Number.isFinite(bvhValue(w)));
  const end = lineEnd(text, header.at);
  if (whole(words(text.slice(header.at, end)))) return 0; // (frame 0 a line, or the first words)
  const re = new RegExp(`[^${SPACE}]+`, 'g');
  re.lastIndex = header.at;
  if (frameLine(text, 0, frames)) { // one frame a line: line by line (blank lines are none)
    for (let f = 0, at = header.at; at <= text.length && f < frames; at = lineEnd(text, at) + 1) {
      const found = words(text.slice(at, lineEnd(text, at)));
      if (found.length && whole(found)) return f;
      if (found.length) f += 1;
    }
    return -1;
  }
  const found = []; // else word by word, as the service reads such a block
  for (let f = 0, m = re.exec(text); m && f < frames; m = re.exec(text)) {
    found.push(m[0]);
    if (found.length < channels) continue;
    if (whole(found)) return f;
    found.length = 0;
    f += 1;
  }
  return -1;
}

const lineEnd = (text, start) => {
  const end = text.indexOf('\n', start);
  return end < 0 ? text.length : end;
};
