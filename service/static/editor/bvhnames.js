// A BVH file's joint names as the service names them (core/bvh.py), for the joint-map
// template (jointmap.js): no imports, so that tests/service/test_editor_joint_names.py runs
// it in Node against the service's reader.

// Blanks as the service's BVH reader splits words at them (Python's str.split): JS's \s also
// holds U+FEFF, and not U+001C-U+001F or U+0085.
const BLANKS = '\\t\\n\\v\\f\\r\\x1c-\\x1f \\x85\\xa0\\u1680\\u2000-\\u200a\\u2028\\u2029\\u202f\\u205f\\u3000';
const WORD = new RegExp(`[^${BLANKS}]+`, 'g');

// The names a joint map may give: every joint of the file as the service names it
// (core/bvh.py): a name is the words after ROOT or JOINT on that line, up to a '{', as
// written (`Left  Hand` keeps its two spaces; `JOINT Neck {` is `Neck`); End Sites are
// `<joint>_end`, a joint's second `<joint>_end2`, and so on, one whose name a joint has
// taking the next free number. Was: each line's text after the keyword, trimmed, which
// listed `Neck {`; the service then joined a name's words with one space (an audit,
// 2026-12-06). For a file the service read: its hierarchy is well formed.
export function fileJoints(text) {
  let head = text.startsWith('\ufeff') ? text.slice(1) : text;
  if (head.includes('\r') && !head.includes('\n')) head = head.replaceAll('\r', '\n');
  const motion = /^[ \t]*MOTION[ \t]*\r?$/m.exec(head);
  if (motion) head = head.slice(0, motion.index);
  const lines = head.split(/\r\n|\r|\n/);
  const words = [];
  lines.forEach((line, k) => {
    for (const m of line.matchAll(WORD)) words.push({ word: m[0], line: k, at: m.index });
  });
  const joints = []; // {name, end: its owner for an End Site}
  const stack = [];
  const count = new Map(); // a joint's End Sites so far
  for (let i = 0; i < words.length; i++) {
    const { word } = words[i];
    if (word === 'ROOT' || word === 'JOINT') {
      let j = i + 1;
      while (j < words.length && words[j].line === words[i].line && words[j].word !== '{') j++;
      if (j === i + 1) continue; // (no name: the service refused the file)
      const first = words[i + 1];
      const last = words[j - 1];
      const name = lines[first.line].slice(first.at, last.at + last.word.length);
      joints.push({ name, end: null });
      stack.push(name);
      i = j - 1;
    } else if (word === 'End' && words[i + 1]?.word === 'Site') {
      const owner = stack[stack.length - 1];
      const k = (count.get(owner) || 0) + 1;
      count.set(owner, k);
      joints.push({ name: k === 1 ? `${owner}_end` : `${owner}_end${k}`, end: owner });
      while (i < words.length && words[i].word !== '}') i++; // its block, closed
    } else if (word === '}') {
      stack.pop();
    }
  }
  const taken = new Set(joints.filter((j) => j.end === null).map((j) => j.name));
  return joints.map(({ name, end }) => {
    if (end === null) return name;
    let out = name;
    for (let k = 2; taken.has(out); k++) out = `${end}_end${k}`;
    taken.add(out);
    return out;
  });
}
