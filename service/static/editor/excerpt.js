// A file's solve sent as an excerpt: the text up to and including its "Frame Time:" line
// with "Frames:" set to 1, then the one line of the frame edited, as frame 0 (the body's
// other fields, units, up, root_position and joint_map among them, as for the whole file:
// the menus' settings; where they say auto, the server infers units from the hierarchy and
// the up axis from its rest pose, else from the frame edited: the excerpt's one frame, so
// the same). The answer's frame line is spliced back into the whole text in place of
// the frame's line: the same text, byte for byte, as the whole file's answer
// (tests/service/test_editor_excerpt.py), from ~10-40 kB sent and answered instead of the
// whole file (7.5 MB each way per solve). Where the excerpt could differ, the whole file
// goes, as before: see ``layoutOf`` for each case and why.
//
// Conventions are the server's reader's (core/bvh.py parse_bvh, _read_frames): the frame
// lines start after the MOTION line, "Frames:" and "Frame Time:"; a block of one frame a
// line is read line by line, each frame's line alone.

import { bvhValue, channelCount, lineValues, motionHeader } from '../bvh.js';

const FRAMES_RE = /^([ \t]*Frames:[ \t]*)(\S+)([ \t]*\r?)$/; // core/bvh.py _FRAMES_RE
const WORD_RE = /\S+/g;

// The committed text's layout (a gesture's solves all start from the same text): worked out
// by reading the text (``layoutOf``, ~10-16 ms for 7.5 MB) where no splice made it, else
// carried over from the text the splice rewrote (``seedLayout``).
let known = { text: null, channels: 0, layout: null };

// Where the frame lines of ``text`` start (``starts[f]``, and the end of each line), or
// null where an excerpt could be read otherwise than the whole file is.
function layoutOf(text, frames, channels) {
  // CR not before LF (classic Mac OS line ends, or mixed): the server reads a CR-only file
  // as LF and gives the answer back with CR; and JS's /m "$" matches before a lone CR
  // (or U+2028/9) where Python's does not: the two could find different MOTION lines.
  if (/\r(?!\n)|[\u2028\u2029]/.test(text)) return null;
  let header;
  try {
    header = motionHeader(text); // (bvh.js: the MOTION line as core/bvh.py's _MOTION_RE finds it)
  } catch {
    return null; // (no MOTION line, or no frame line: nothing to excerpt)
  }
  if (!FRAMES_RE.test(text.slice(...header.frames))) return null;
  const { at } = header;
  // Other than printable ASCII, tab, CR, LF in the frames: Python's and JS's white space
  // differ there (U+FEFF is space to JS's \s, not to str.isspace; \x1c-\x1f the other way):
  // where a frame's line ends, or what is blank, could be read differently.
  if (/[^\t\n\r\x20-\x7e]/.test(text.slice(at))) return null;
  // Fewer characters than the values need: the server reads the whole block (and refuses
  // it where a line is short), whatever the frame (core/bvh.py _read_frames).
  if (frames * channels * 2 > text.length - at + 1) return null;
  // Frames not one a line (wrapped over lines, blank lines among them or after them): the
  // server finds a frame's values by counting words over the whole block
  // (core/bvh.py one_frame_a_line, _read_frame_words); one line alone is no such block.
  if (/^[^\S\n]*(?:\n|$)/.test(text.slice(at, text.indexOf('\n', at) + 1 || text.length))) return null;
  if (/\n[^\S\n]*\n/.test(text.slice(at))) return null;
  const starts = [at];
  for (let i = text.indexOf('\n', at); i >= 0; i = text.indexOf('\n', i + 1)) starts.push(i + 1);
  const last = text.slice(starts.at(-1));
  const lines = starts.length - 1 + (last !== '' && /\S/.test(last) ? 1 : 0);
  if (lines !== frames) return null;
  // Cut short (its last line holds fewer values than a frame's): every answer of the whole
  // file says so (``cut_short``), and a frame at or after the cut is not one a line.
  const lastLine = text.slice(starts[frames - 1], lineEnd(text, starts[frames - 1]));
  if ((lastLine.match(WORD_RE) || []).length < channels) return null;
  return { framesLine: header.frames, at, starts };
}

const lineEnd = (text, start) => {
  const end = text.indexOf('\n', start);
  return end < 0 ? text.length : end;
};

// The layout kept only while its text is the committed one (``text``; null: no file): a
// text no longer shown is let go (a 7.5 MB file's old text was held until the next solve).
export function forgetLayout(text) {
  if (known.text !== text) known = { text: null, channels: 0, layout: null };
}

// The text ``edit.to``, an answer spliced into ``edit.from`` (``splice``), is the committed
// one now (solve.js, at a gesture's commit): its layout is ``edit.from``'s with the lines
// after the frame's moved by the line's change of length, where that is what ``layoutOf``
// would find (``layoutAfter``); else it is worked out when first asked for, as before. Each
// gesture's first solve read the whole new text to work it out (~10-16 ms, 7.5 MB).
export function seedLayout(edit) {
  const l = layoutAfter(edit);
  if (l) known = { text: edit.to, channels: edit.channels, layout: l };
}

// ``layoutOf(edit.to)`` without reading it, or null where the line written could change
// what ``layoutOf`` finds (its tests, each on the one line that differs; the text before
// the frame's line, the header among it, is the same): a CR not before an LF, a character
// other than printable ASCII, a blank line (or, the last, too few values), too few
// characters for the frames' values. Node runs it against ``layoutOf``
// (tests/service/test_editor_commit_reads.py).
export function layoutAfter({ to, start, end, after, frame, frames, channels, layout: l, fromLength }) {
  if (/[^\t\r\x20-\x7e]|\r(?!$)/.test(after) || (after.endsWith('\r') && end === fromLength)) return null;
  if (frame === frames - 1 ? (after.match(WORD_RE) || []).length < channels : !/\S/.test(after)) return null;
  if (frames * channels * 2 > to.length - l.at + 1) return null;
  const delta = after.length - (end - start);
  const starts = l.starts.slice();
  for (let i = frame + 1; i < starts.length; i += 1) starts[i] += delta;
  return { framesLine: l.framesLine, at: l.at, starts };
}

// (exported for the test above: Node compares it with ``layoutAfter``)
export const readLayout = layoutOf;

// A file too big for one request (the service's 413, POSE_MAX_BODY_BYTES) read from its
// first frame, as its solves are sent (the limit's detail says so): the inspection's
// excerpt, frame 0's line after the head with "Frames: 1", and the frames the file declares
// (``frames``) and where its frames start (``at``); null where no excerpt can be cut (no MOTION header, "Frames:" no count,
// lines ended by a CR alone, frame 0's line blank). Whether the whole file is read as
// the excerpts are, one frame a line, whole, is known only with its channels (the
// inspection's): ``layoutOf`` then (inspect.js). A file over 8 MiB could not be opened at all,
// its 413 telling the user what an API client sends.
export function firstFrame(text) {
  if (/\r(?!\n)|[\u2028\u2029]/.test(text)) return null;
  let header;
  try {
    header = motionHeader(text);
  } catch {
    return null;
  }
  const [fs, fe] = header.frames;
  const m = FRAMES_RE.exec(text.slice(fs, fe));
  const frames = m ? Number(m[2]) : NaN;
  if (!Number.isInteger(frames) || frames < 1) return null;
  const { at } = header;
  const line = text.slice(at, lineEnd(text, at));
  if (!/\S/.test(line)) return null;
  const framesLine = text.slice(fs, fe).replace(FRAMES_RE, (_, a, n, b) => `${a}1${b}`);
  return { bvh: `${text.slice(0, fs)}${framesLine}${text.slice(fe, at)}${line}\n`, frames, at, line };
}

// The committed text's entry (``known``): its layout, and the cut last made of it.
function entryOf(text, frames, channels) {
  if (known.text !== text || known.channels !== channels) {
    known = { text, channels, layout: layoutOf(text, frames, channels) };
  }
  return known;
}

// Whether ``text`` holds one frame a line as the server reads it (``layoutOf``: no blank
// line among or after the frames, as many lines as frames, the last whole, printable ASCII):
// a frame's line is then the frame, whatever it holds (rows.js frameRow: a broken line).
export const oneFrameALine = (text, frames, channels) => Boolean(entryOf(text, frames, channels).layout);

// The values of ``frame`` of the committed text ``text`` (a Float64Array of ``channels``),
// read from its line where the text's layout is (worked out once per text, and kept for
// its excerpts), or null where it has none: a scrub walked the text to the frame's line
// (bvh.js frameValues, ~4-5 ms a frame on a 7.5 MB file). The same values: the layout's
// lines are the frames' lines frameValues counts (``layoutOf`` refuses blank ones).
export function committedRow(text, frame, frames, channels) {
  const { layout: l } = entryOf(text, frames, channels);
  if (!l) return null;
  return lineValues(text.slice(l.starts[frame], lineEnd(text, l.starts[frame])), channels);
}

// The excerpt's parts for ``frame`` of the entry's text: the head (the text up to its frame
// lines, ``Frames: 1``) and the frame's line, or null where its values would be refused.
// Kept with the entry: a gesture's solves all cut the same frame of the same text (its
// line's every value was checked, and the head written, for each: 13 us a solve).
function cutOf(entry, frame, channels) {
  if (entry.cut && entry.cut.frame === frame) return entry.cut.parts;
  const { text, layout: l } = entry;
  const start = l.starts[frame];
  const end = lineEnd(text, start);
  const line = text.slice(start, end);
  // A frame whose values the server would refuse: its 422 names the line and frame of the
  // whole file (an excerpt's would say frame 0 on another line); so would a wrong count.
  const words = line.match(WORD_RE) || [];
  const refused = words.length !== channels
    || !words.every((w) => Number.isFinite(bvhValue(w))); // (bvh.js: as every frame is read)
  let parts = null;
  if (!refused) {
    const [fs, fe] = l.framesLine;
    const framesLine = text.slice(fs, fe).replace(FRAMES_RE, (_, a, n, b) => `${a}1${b}`);
    parts = { head: text.slice(0, fs) + framesLine + text.slice(fe, l.at), start, end, line };
  }
  entry.cut = { frame, parts };
  return parts;
}

// The excerpt of ``body`` (a /v1/bvh/solve request of the whole file), or null where the
// whole file must go. ``info``: the inspect answer (frames, joints' channels, cut_short).
export function excerptOf(body, info) {
  if (!info || info.cut_short) return null; // (cut short: its answers say so; layoutOf too)
  const channels = channelCount(info);
  const text = body.bvh;
  const frame = body.frame;
  if (!Number.isInteger(frame) || frame < 0 || frame >= info.frames || channels === 0) return null;
  const entry = entryOf(text, info.frames, channels);
  const l = entry.layout;
  if (!l) return null;
  const parts = cutOf(entry, frame, channels);
  if (!parts) return null;
  const { head, start, end, line } = parts;
  return {
    body: { ...body, bvh: `${head}${line}\n`, frame: 0 },
    // The whole file's answer from the excerpt's (``data``: its frame line in place of the
    // frame's, the real frame), and ``row``, the frame's values as that line holds them
    // (bvh.js lineValues: what frameValues finds walking the new text, whose lines are the
    // layout's; null where the line is no frame's values, and the page walks the text as
    // before): the page drew each answer's frame by reading the whole new text (rows.js
    // frameRow), 0.8-49 ms an answer on 1-7.5 MB files, 0.08 ms from the row. ``edit``:
    // how the new text differs from ``text`` (its frame's line, ``before``, become
    // ``after``), for the commit (solve.js): the new text's layout (``seedLayout``) and the
    // undo step's change (history.js) without reading either text. Null where the answer is
    // not the excerpt with that line rewritten.
    splice(answer) {
      const got = answer && answer.bvh;
      if (typeof got !== 'string' || !got.startsWith(head) || !got.endsWith('\n')) return null;
      const edited = got.slice(head.length, -1);
      if (edited.includes('\n')) return null;
      const data = { ...answer, bvh: text.slice(0, start) + edited + text.slice(end), frame };
      const edit = {
        from: text, to: data.bvh, fromLength: text.length, start, end, before: line, after: edited,
        frame, frames: info.frames, channels, layout: l,
      };
      return { data, row: lineValues(edited, channels), edit };
    },
  };
}
