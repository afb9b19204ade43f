// How a text became another: the lines that differ (history.js: an undo step of a file
// holds its change, not the file). No imports: Node runs it too (a test's).

// How ``a`` became ``b``: ``head`` characters alike at the start and ``tail`` at the end
// (whole lines), and between them the runs of lines that differ (``hunks``: each its first
// line there, the lines it replaced, ``from``, and those it wrote, ``to``, joined by LF).
// Where both hold as many lines between, each run of changed lines is a hunk of its own
// (a Reset undoing edits at frames 10 and 6,000 holds those two lines, not the 5,990
// between); else the lines between are one hunk. Null if they are the same text.
export function diff(a, b) {
  if (a === b) return null;
  let head = commonHead(a, b);
  head = head > 0 ? a.lastIndexOf('\n', head - 1) + 1 : 0; // (from a line's start)
  let tail = commonTail(a, b, Math.min(a.length, b.length) - head);
  const end = a.length - tail; // (to a line's end: an LF, or the end of the text)
  if (end < a.length && a[end] !== '\n') {
    const lf = a.indexOf('\n', end);
    tail = lf < 0 ? 0 : a.length - lf;
  }
  const from = a.slice(head, a.length - tail).split('\n');
  const to = b.slice(head, b.length - tail).split('\n');
  const hunks = [];
  if (from.length !== to.length) {
    hunks.push(hunk(0, from, to));
  } else {
    for (let i = 0; i < from.length; i += 1) {
      if (from[i] === to[i]) continue;
      let j = i + 1;
      while (j < from.length && from[j] !== to[j]) j += 1;
      hunks.push(hunk(i, from.slice(i, j), to.slice(i, j)));
      i = j;
    }
  }
  return { head, tail, hunks };
}

// The change of a text whose one line (``head`` characters before it, ``tail`` after it, no
// LF in either line) was ``before`` and is ``after``: what ``diff`` finds of the two texts
// (a hunk as long, the same texts both ways), from the line alone. Null if it is the same.
export function lineChange(head, tail, before, after) {
  if (before === after) return null;
  return { head, tail, hunks: [hunk(0, [before], [after])] };
}

// A hunk's lines as strings of their own: a slice of a text is a view that keeps the whole
// text alive (V8), and a step holding one would hold a copy of the file after all.
const own = (s) => JSON.parse(JSON.stringify(s));
const hunk = (line, from, to) => ({
  line, lines: [from.length, to.length], from: own(from.join('\n')), to: own(to.join('\n')),
});

// ``change`` applied to ``text``: forward (``a`` to ``b``), or backward (``b`` to ``a``).
export function apply(text, { head, tail, hunks }, forward) {
  const lines = text.slice(head, text.length - tail).split('\n');
  for (let k = hunks.length - 1; k >= 0; k -= 1) { // (the last first: the lines before keep their place)
    const h = hunks[k];
    lines.splice(h.line, h.lines[forward ? 0 : 1], forward ? h.to : h.from);
  }
  return text.slice(0, head) + lines.join('\n') + text.slice(text.length - tail);
}

const CHUNK = 4096;

// How many characters ``a`` and ``b`` have alike at their start (a chunk at a time, then one).
function commonHead(a, b) {
  const n = Math.min(a.length, b.length);
  let i = 0;
  while (i + CHUNK <= n && a.slice(i, i + CHUNK) === b.slice(i, i + CHUNK)) i += CHUNK;
  while (i < n && a.charCodeAt(i) === b.charCodeAt(i)) i += 1;
  return i;
}

// How many characters, at most ``limit``, ``a`` and ``b`` have alike at their end.
function commonTail(a, b, limit) {
  const n = Math.max(limit, 0);
  let i = 0;
  const chunk = (s, k) => s.slice(s.length - k - CHUNK, s.length - k);
  while (i + CHUNK <= n && chunk(a, i) === chunk(b, i)) i += CHUNK;
  while (i < n && a.charCodeAt(a.length - 1 - i) === b.charCodeAt(b.length - 1 - i)) i += 1;
  return i;
}
