// A file's inspection (``POST v1/bvh/inspect``) as it is opened or read again: the whole file,
// or, over the service's body limit, an excerpt of one frame (editor/excerpt.js).

import { api, ApiError } from './api.js';
import { channelCount } from '../bvh.js';
import { firstFrame, readLayout } from './excerpt.js';

const lineEnd = (text, start) => {
  const end = text.indexOf('\n', start);
  return end < 0 ? text.length : end;
};

// ``POST v1/bvh/inspect`` of ``text`` (the other fields: ``fields``). A file the service
// refuses as too big (413: over its POSE_MAX_BODY_BYTES, 8 MiB by default) is read from its
// first frame (``firstFrame``), as its solves are sent, where the whole file is read as
// those excerpts are (``readLayout``: one frame a line, as many as "Frames:" says, the last
// whole): the answer is the whole file's, its frames the file's count. Else the 413 says
// why the page cannot send it a frame at a time. (A 14 MB file could not be opened: the
// banner told the user to send "an excerpt", which only the page can.)
//
// The limit is the server's as it says it (GET v1/models max_body_bytes, read as the page
// connects: ``knowLimit``; or a 413's detail), else the service's default: a file whose
// body is over it goes as an excerpt at once, where it can; one that cannot goes whole
// while the limit is not known (the service's may be higher). The first big file was
// uploaded whole only to be refused (9.5 MB for a 413), and a file under the limit in
// characters but over it as a JSON body (each line end sent as two bytes, \n) was uploaded
// for a 413 each time. A server whose operator raised the limit was sent a file over the
// default as an excerpt all the same (its other rows unread: rows_warning), the default
// in force as no 413 came to say otherwise.
const DEFAULT_LIMIT = 8 * 1024 * 1024; // (service/settings.py max_body_bytes)
const limit = { bytes: DEFAULT_LIMIT, said: false }; // (said: by the server)

// The server's body limit as it says it (``bytes``; not a positive whole number: an older
// server's answer without it, and the limit stays as it was).
export function knowLimit(bytes) {
  if (Number.isInteger(bytes) && bytes > 0) Object.assign(limit, { bytes, said: true });
}

// The bytes of the JSON body sending ``text`` (and a few fields), or a bound under which it
// surely is: each character one byte, those JSON escapes (\n, \") two, other control
// characters six, past U+007F (UTF-8) two or three.
function bodyBytes(text) {
  if (text.length * 6 + 1024 < limit.bytes) return text.length; // (under it whatever it holds)
  let n = text.length + 1024;
  for (const m of text.matchAll(/[\n\r\t"\\]+|[\0-\x1f]+|[\x80-\u07ff]+|[\u0800-\uffff]+/g)) {
    const c = m[0].charCodeAt(0);
    n += m[0].length * (c < 0x20 && !'\n\r\t'.includes(m[0][0]) ? 5 : c >= 0x800 ? 2 : 1);
  }
  return n;
}

const tooBig = (bytes) => new ApiError(413, 'Request body too large', `body of ${bytes} bytes `
  + `or more exceeds the ${limit.bytes}-byte limit (the server's POSE_MAX_BODY_BYTES${
    limit.said ? '' : ' by default'})`);

// How ``text`` is sent a frame at a time: its first frame's excerpt (``firstFrame``), its
// channels as its CHANNELS lines declare them (checked against the answer's) and its layout
// (``readLayout``), or ``why`` not.
function framesOf(text) {
  const first = firstFrame(text);
  if (!first) return { why: 'this one has no such frames (no Frames: count, or lines ended by CR alone)' };
  const channels = [...text.slice(0, first.at).matchAll(/^[ \t]*CHANNELS[ \t]+(\d+)/gim)]
    .reduce((n, m) => n + Number(m[1]), 0);
  const layout = readLayout(text, first.frames, channels);
  const why = `this one does not (${first.frames} frames of ${channels} values each declared)`;
  return { first, channels, layout, why };
}

export async function inspect(text, fields) {
  const bytes = bodyBytes(text);
  let err = bytes > limit.bytes ? tooBig(bytes) : null;
  const big = err && /HIERARCHY/i.test(text.slice(0, 65536)) ? framesOf(text) : null;
  if (err && !limit.said && big && !big.layout) err = null; // (the service's limit may be higher)
  if (!err) {
    try {
      return await api('POST', 'v1/bvh/inspect', { bvh: text, ...fields });
    } catch (refused) {
      if (!(refused instanceof ApiError && refused.status === 413)) throw refused;
      err = refused;
      const said = /(\d+)-byte limit/.exec(err.detail);
      if (said) knowLimit(Number(said[1]));
    }
  }
  const mb = `${(text.length / 1e6).toFixed(1)} MB`;
  if (!/HIERARCHY/i.test(text.slice(0, 65536))) { // (binary junk: said so, as a small one is)
    throw new ApiError(422, 'Not a BVH file', `no HIERARCHY keyword (${mb}, over the server's limit for one request)`);
  }
  const most = err.detail.split(/\.\s/)[0]; // (the rest tells an API client what to send)
  const notOne = (why) => new ApiError(413, err.title, `the file (${mb}) is over the server's `
    + `limit for one request (${most}), and the editor sends a big file a frame at a time `
    + `only where it holds one frame a line, as many as its Frames: line says, the last one `
    + `whole; ${why}`, err.requestId);
  const { first, channels, layout, why } = big || framesOf(text);
  if (!layout) throw notOne(why);
  // (frame 0's line in the excerpt, or the line of the frame asked for: one whose frame 0 is broken)
  const line = text.slice(layout.starts[fields.frame], lineEnd(text, layout.starts[fields.frame]));
  const bvh = `${first.bvh.slice(0, first.bvh.length - first.line.length - 1)}${line}\n`;
  const res = await api('POST', 'v1/bvh/inspect', { ...fields, bvh, frame: 0 });
  if (res.data.cut_short || channelCount(res.data) !== channels) throw notOne(why);
  return { ...res, data: { ...res.data, frames: first.frames, frame: fields.frame } };
}
