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
let bodyLimit = Infinity; // (bytes: the last 413's; a file over it goes as an excerpt at once)

export async function inspect(text, fields) {
  let err;
  try {
    if (text.length > bodyLimit) { // (a 413 again: not uploaded again, a few MB for nothing)
      throw new ApiError(413, 'Request body too large', `body of ${text.length} bytes or more `
        + `exceeds the ${bodyLimit}-byte limit (the server's POSE_MAX_BODY_BYTES)`);
    }
    return await api('POST', 'v1/bvh/inspect', { bvh: text, ...fields });
  } catch (refused) {
    if (!(refused instanceof ApiError && refused.status === 413)) throw refused;
    err = refused;
  }
  const said = /(\d+)-byte limit/.exec(err.detail);
  if (said) bodyLimit = Number(said[1]);
  const mb = `${(text.length / 1e6).toFixed(1)} MB`;
  if (!/HIERARCHY/i.test(text.slice(0, 65536))) { // (binary junk: said so, as a small one is)
    throw new ApiError(422, 'Not a BVH file', `no HIERARCHY keyword (${mb}, over the server's limit for one request)`);
  }
  const limit = err.detail.split(/\.\s/)[0]; // (the rest tells an API client what to send)
  const notOne = (why) => new ApiError(413, err.title, `the file (${mb}) is over the server's `
    + `limit for one request (${limit}), and the editor sends a big file a frame at a time `
    + `only where it holds one frame a line, as many as its Frames: line says, the last one `
    + `whole; ${why}`, err.requestId);
  const first = firstFrame(text);
  if (!first) throw notOne('this one has no such frames (no Frames: count, or lines ended by CR alone)');
  // (its channels as its CHANNELS lines declare them, checked against the answer's)
  const channels = [...text.slice(0, first.at).matchAll(/^[ \t]*CHANNELS[ \t]+(\d+)/gim)]
    .reduce((n, m) => n + Number(m[1]), 0);
  const not = `this one does not (${first.frames} frames of ${channels} values each declared)`;
  const layout = readLayout(text, first.frames, channels);
  if (!layout) throw notOne(not);
  // (frame 0's line in the excerpt, or the line of the frame asked for: one whose frame 0 is broken)
  const line = text.slice(layout.starts[fields.frame], lineEnd(text, layout.starts[fields.frame]));
  const bvh = `${first.bvh.slice(0, first.bvh.length - first.line.length - 1)}${line}\n`;
  const res = await api('POST', 'v1/bvh/inspect', { ...fields, bvh, frame: 0 });
  if (res.data.cut_short || channelCount(res.data) !== channels) throw notOne(not);
  return { ...res, data: { ...res.data, frames: first.frames, frame: fields.frame } };
}
