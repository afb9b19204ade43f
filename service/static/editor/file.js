// A BVH file: its frames in the page's world (the service's joint map, static/bvh.js's forward
// kinematics), and open (picker or drop), scrub, close.

import * as THREE from 'three';
import { anchorPoints, channelCount, forwardKinematics } from '../bvh.js';
import { $, doc, history, solver, state, ui } from './state.js';
import { api, ApiError, clearError, showError } from './api.js';
import {
  cancelSolves, clonePose, forgetLastSolve, pushHistory, restore, whenCommitted,
} from './solve.js';
import { clearHistory } from './history.js';
import { buildCharacterBones, buildSkeleton, camera, centreFloor, controls, UP } from './scene.js';
import { endDrag } from './interaction.js';
import { refresh, refreshPanel } from './panel.js';
import { offerTemplate, readMap, showMap } from './jointmap.js';
import { committedRow } from './excerpt.js';
import { inspect } from './inspect.js';
import { brokenRow, firstWholeFrame, frameRow, releaseTexts } from './rows.js';

// ------------------------------------------------------------------------------------
// A file's frames: forward kinematics, the page's world
// ------------------------------------------------------------------------------------
// Forward kinematics of one frame's values: every joint, and the canonical points (file units).
export function rowFrame(row) {
  const joints = doc.info.joints;
  const fk = forwardKinematics(joints, row, doc.settings && doc.settings.root === 'add');
  return { fk, points: anchorPoints(joints, doc.info.anchors, fk) };
}

// The same of one frame of a text; ``known``: the frame's values, where the text's maker
// knows them (frameRow).
export const fileFrame = (text, frame, known = null) => rowFrame(frameRow(text, frame, known));

export const toWorld = (p) => new THREE.Vector3(p[0], p[1], p[2]).applyMatrix4(doc.toWorld).toArray();
export const toFile = (p) => new THREE.Vector3(p[0], p[1], p[2]).applyMatrix4(doc.fromWorld).toArray();

// The 21 handles (world) of a frame of a text (``known``: as fileFrame's).
export function filePose(text, frame, known = null) {
  const { points } = fileFrame(text, frame, known);
  return Object.fromEntries(Object.entries(points).map(([k, p]) => [k, toWorld(p)]));
}

// ------------------------------------------------------------------------------------
// BVH files: open (picker or drop), read again, scrub, close
// ------------------------------------------------------------------------------------
// How a file is read: the menus' settings, as a file opened from the picker starts them
// (units and up axis found anew: a choice made for the file before, inches say, drew a
// centimetre file as a giant; the root's channels as BVH has them), unless no file is open
// or tried: then the menus hold what the user chose for the next file (an inches, +Z up
// file was refused for its units, "pick them in the Units menu", though picked there just
// before, the menu back at auto). A file closed (a Sample) puts them back to the defaults.
const MENUS = { units: 'bvh-units', up: 'bvh-up', root: 'bvh-root' };
const DEFAULT_SETTINGS = { units: 'auto', up: 'auto', root: 'replace' };

function menuSettings() {
  return Object.fromEntries(Object.entries(MENUS).map(([key, id]) => [key, $(id).value]));
}

function showSettings(settings) {
  for (const [key, id] of Object.entries(MENUS)) $(id).value = settings[key];
}

// The request fields of the menus' settings (what "auto" or the default leaves out).
function fileSettings({ units, up, root }) {
  const out = {};
  if (units !== 'auto') out.units = Number.isFinite(Number(units)) ? Number(units) : units;
  if (up !== 'auto') out.up = up;
  if (root !== 'replace') out.root_position = root;
  return out;
}

// The page's world: metres, +Y up, the character as opened facing +Z with its pelvis
// above the origin and its lowest joint on the grid.
function worldMapping(info, frame0) {
  const s = info.metres_per_unit;
  const m = new THREE.Matrix4().makeScale(s, s, s);
  if (info.up === '+Z') m.premultiply(new THREE.Matrix4().makeRotationX(-Math.PI / 2)); // (x, y, z) -> (x, z, -y)
  const at = (p) => new THREE.Vector3(...p).applyMatrix4(m);
  const left = at(frame0.points.left_hip).sub(at(frame0.points.right_hip));
  const forward = new THREE.Vector3().crossVectors(left, UP);
  const yaw = Math.atan2(forward.x, forward.z);
  m.premultiply(new THREE.Matrix4().makeRotationY(-yaw));
  const pelvis = at(frame0.points.pelvis);
  const lowest = Math.min(...frame0.fk.pos.map((p) => at(p).y));
  m.premultiply(new THREE.Matrix4().makeTranslation(-pelvis.x, -lowest, -pelvis.z));
  return m;
}

let opening = 0;
let picked = 0; // files picked or dropped: a later one (or a Sample) takes an earlier one's place

// A file being opened, or the open one read again: editing waits for the answer, which
// replaces the pose, the file and the history (an edit made meanwhile was drawn, then
// lost when it came), and the status says so. Choosing a sample or another file is not an
// edit: it gives this one up (cancelOpening) or takes its place.
function startReading(text) {
  ui.reading = text;
  $('status').textContent = `${text}… (editing waits)`;
  $('status').classList.add('busy');
  refreshPanel();
}

function stopReading() {
  ui.reading = null;
  $('status').classList.remove('busy');
  refreshPanel();
}

// A file's opening still on its way is given up (a Sample chosen meanwhile: the later
// choice stands; the file's late answer opened it over the sample's edits, unasked).
export function cancelOpening() {
  opening += 1; // (an answer on its way finds its ticket stale and is dropped)
  picked += 1; // (as does a file whose bytes are still being read)
  if (doc.tried) showSettings(DEFAULT_SETTINGS); // (no file tried: the menus are for the next)
  doc.tried = null; // (nor does a units / up change re-open it)
  if (ui.reading) {
    stopReading();
    $('status').textContent = ui.connected ? 'connected' : 'server not ready';
  }
}

// Open ``text`` as the file ``name``; ``original`` is the file as opened (Reset returns to
// it): the text itself, unless the open file is read ``again`` with other units, up axis,
// root channels or joint map (its edits kept, at the frame shown when the answer comes).
// ``jointMap``: sent with its inspection and, once open, its solves. ``yes``: the state
// shown (the open file's, or a sample's) the user agreed to replace (``replaceable``), kept
// with the file tried so that re-trying it after a refusal asks only about newer edits.
export async function openText(text, name, {
  original = text, encoding = 'utf-8', jointMap = null, yes = null, again = false,
} = {}) {
  const settings = menuSettings(); // (as sent: the menus may change before the answer)
  doc.tried = { text: original, name, encoding, jointMap, yes, settings };
  const ticket = ++opening;
  startReading(again ? `reading ${name} again` : `opening ${name}`);
  let res;
  try {
    const map = jointMap ? { joint_map: jointMap } : {};
    // (read at its first frame the page reads whole: frame 0 where it is, as nearly always)
    const frame = Math.max(firstWholeFrame(text), 0);
    res = await inspect(text, { frame, ...fileSettings(settings), ...map });
    if (ticket !== opening) return;
  } catch (err) {
    if (ticket !== opening) return;
    stopReading();
    offerTemplate(err, text);
    const same = doc.active && name === doc.name && original === doc.original;
    if (same && doc.settings) showSettings(doc.settings); // the open file stays as it was read: say so
    const stays = doc.active && !same ? ` (${doc.name} stays open)` : '';
    showError(err instanceof ApiError
      ? new ApiError(err.status, err.title, `${name}${stays}: ${menuHint(err.detail)}`, err.requestId)
      : err);
    if (!(err instanceof ApiError && err.status === 0)) { // (unreachable: api() said so)
      $('status').textContent = ui.connected ? 'connected' : 'server not ready';
    }
    return;
  }
  const opened = { info: res.data, name, original, encoding, jointMap, settings };
  // read again: the file and frame as they are when the answer comes (an option changed
  // meanwhile re-solves the file: that answer is an edit too, and is waited for)
  if (!again) {
    showOpened({ ...opened, text, frame: 0 });
    return;
  }
  whenCommitted(() => {
    if (ticket === opening) showOpened({ ...opened, text: doc.text, frame: doc.frame, kept: keptEdits() });
  });
}

// A refusal of the file's units or up axis tells an API client what to send ("units":
// "in"); in this page a menu sends it, so the banner names the menu too (a user's audit
// read JSON advice where the fix was the Units menu).
function menuHint(detail) {
  if (/^units: /.test(detail)) return `${detail} (here: pick them in the Units menu)`;
  if (/^up: /.test(detail)) return `${detail} (here: pick it in the Up axis menu)`;
  return detail;
}

// What a file read again keeps besides its text: the pins, and the targets, each carried
// with its joint (the same offset from it in the file's units: where it was on the
// figure, whose handles the new reading scales, turns or moves). Before the new reading.
function keptEdits() {
  const { points } = fileFrame(doc.text, doc.frame);
  const targets = [...state.targets].map(([joint, p]) => {
    const at = toFile(p);
    return [joint, at.map((v, i) => v - points[joint][i])];
  });
  return { targets, pins: [...state.pins] };
}

function showOpened({ info, text, name, original, encoding, jointMap, settings, frame, kept = null }) {
  stopReading();
  endDrag(false);
  cancelSolves();
  if (!kept) forgetLastSolve(); // (a file opened; one read again keeps its last solve)
  Object.assign(doc, { active: true, name, original, text, shown: text, info, frame: 0, encoding, jointMap, settings });
  releaseTexts(true); // (the file's before: its texts, its rows)
  // the yes to replacing what was shown is spent: it held that file's texts (two copies of
  // a file no longer open, for as long as this one was)
  if (doc.tried) doc.tried.yes = null;
  showMap(jointMap);
  // the view set up from frame 0, or, where the page has no pose for it (a broken line),
  // from the frame the service read (the answer's joints: a file whose frame 0 is broken is
  // inspected at its first whole one; it was set up from NaN, the view blank)
  const frame0 = fileFrame(text, 0);
  const drawn = frame0.fk.pos.every((p) => p.every(Number.isFinite));
  const read = { points: info.points, fk: { pos: info.positions } };
  doc.toWorld = worldMapping(info, drawn ? frame0 : read);
  doc.fromWorld = doc.toWorld.clone().invert();
  buildSkeleton();
  buildCharacterBones();
  ui.hovered = null;
  clearHistory();
  const at = Math.min(Math.max(frame, 0), lastFrame(info));
  const { points } = fileFrame(text, at);
  const targets = (kept ? kept.targets : []).map(([joint, d]) => [joint, toWorld(points[joint].map((v, i) => v + d[i]))])
    .filter(([, p]) => p.every(Number.isFinite)); // (none on a broken frame)
  restore({ pose: filePose(text, at), targets, pins: kept ? kept.pins : [], text, frame: at });
  pushHistory();
  // (the frame shown's pelvis: read again, it may be far from 0; a broken frame's, the
  // frame the service read)
  const posed = state.pose.pelvis.every(Number.isFinite);
  const pelvis = posed ? state.pose.pelvis : toWorld(info.points.pelvis);
  controls.target.set(pelvis[0], pelvis[1], pelvis[2]);
  camera.position.set(pelvis[0] + 0.85, pelvis[1] + 0.5, pelvis[2] + 3.3);
  controls.update();
  doc.followed = { frame: posed ? at : info.frame, pelvis: [...pelvis] };
  for (const input of [$('bvh-frame'), $('bvh-frame-number')]) {
    input.max = String(lastFrame(info));
    input.value = String(at);
  }
  delete $('bvh-frame-number').dataset.editing;
  $('bvh-loaded').hidden = false;
  $('bvh-name').textContent = name;
  // (to 2 decimals: a Frame Time of 0.041667 s is 24 fps, not 23.9998; 0.0417083 s, 23.98)
  const fps = info.frame_time > 0 ? ` @ ${(1 / info.frame_time).toFixed(2).replace(/\.?0+$/, '')} fps` : '';
  $('bvh-meta').textContent = `${info.joints.length} joints, ${info.frames} frames${fps}; `
    + `${info.scheme} map, units ${info.units}, up ${info.up}`;
  $('export').textContent = 'Export BVH';
  $('export').title = 'Download the edited BVH file';
  $('reset').title = 'Back to the file as opened, no targets, no pins';
  $('sample').value = '';
  $('status').textContent = ui.connected ? 'connected' : 'server not ready';
  clearError();
  refresh();
  warnOpened(info, posed ? null : brokenRow(text, at));
}

// The last frame a file's text holds (0-based): of one cut short, the frame the cut is in,
// where part of it is there (it has no pose to draw: the banner says why), else the one
// before it; the frames after it are not in the text at all (a file cut inside frame 235
// of 339 could be scrubbed to 338, an empty view each: a user's audit).
export function lastFrame(info) {
  const cut = info.cut_short;
  const last = cut ? (cut.values > 0 ? cut.frame : cut.frame - 1) : info.frames - 1;
  return Math.max(Math.min(last, info.frames - 1), 0);
}

// What the server found in the file as read (/v1/bvh/inspect): cut short (its frames from
// the cut on lost: an interrupted copy), units that make the rest pose's leg no person's
// (a centimetre file read as inches: drawn as a giant), an up axis read from a rest pose
// that the frame's root turns upright along the other one (drawn lying down), root
// channels whose other reading stands the figure on the floor (ReActIdle's, read the BVH
// way: 0.7 m under it, drawn with its lowest joint on the grid, so nothing looked wrong), or
// left and right joints named for the other side (solved as the body it is). The file opens
// either way; without a word, the cut frame was drawn as half a body and the giant as asked.
// ``broken``: why the frame shown has no pose (brokenRow), said first as a "Broken frame"
// (a file whose frame 0 is broken: the rows_warning names the same line).
function warnOpened(info, broken = null) {
  const root = info.root_warning && (info.root_warning.startsWith('root_position:')
    ? `${info.root_warning} (the Root channels menu)` // (a body that cannot move: no menu helps)
    : info.root_warning);
  const up = info.up_warning && `${info.up_warning} (the Up axis menu)`;
  const said = [info.cut_short && info.cut_short.detail, !broken && info.rows_warning,
    info.units_warning, up, root, info.sides_warning].filter(Boolean);
  if (broken) {
    showError(new ApiError(-1, 'Broken frame', [broken, ...said].join('; ')));
    return;
  }
  if (!said.length) return;
  const title = info.cut_short || info.rows_warning ? 'Broken file' : info.units_warning ? 'Units'
    : info.up_warning ? 'Up axis' : info.root_warning ? 'Root channels' : 'Sides';
  showError(new ApiError(-1, title, `${doc.name}: ${said.join('; ')}`));
}

// A file's bytes as text, and how to write them back byte for byte: UTF-8 (a byte order
// mark kept as the text's first character), else ISO-8859-1, one character per byte (an
// exporter's Latin-1 joint name 'abdom\xe9n'; file.text() turned it into U+FFFD, and the
// export wrote that instead of the byte). UTF-16 with its byte order mark (Windows tools'
// "Unicode"), written back so: read as Latin-1, it was refused as "not a BVH file".
export function decodeFile(bytes) {
  const le = bytes[0] === 0xff && bytes[1] === 0xfe;
  if ((le || (bytes[0] === 0xfe && bytes[1] === 0xff)) && bytes.length % 2 === 0) {
    const encoding = le ? 'utf-16le' : 'utf-16be';
    try {
      return { text: new TextDecoder(encoding, { fatal: true, ignoreBOM: true }).decode(bytes), encoding };
    } catch { /* (not UTF-16 after all: below) */ }
  }
  try {
    return { text: new TextDecoder('utf-8', { fatal: true, ignoreBOM: true }).decode(bytes), encoding: 'utf-8' };
  } catch {
    let text = '';
    for (let i = 0; i < bytes.length; i += 8192) {
      text += String.fromCharCode(...bytes.subarray(i, i + 8192));
    }
    return { text, encoding: 'latin-1' };
  }
}

// The bytes of ``text`` in ``encoding`` (``decodeFile``'s inverse).
export function encodeFile(text, encoding) {
  if (encoding === 'utf-16le' || encoding === 'utf-16be') { // (the mark: the text's first character)
    const out = new DataView(new ArrayBuffer(text.length * 2));
    for (let i = 0; i < text.length; i += 1) out.setUint16(2 * i, text.charCodeAt(i), encoding === 'utf-16le');
    return new Uint8Array(out.buffer);
  }
  if (encoding !== 'latin-1') return new TextEncoder().encode(text);
  return Uint8Array.from(text, (c) => c.charCodeAt(0)); // edits write ASCII digits only
}

// What giving up the state shown loses: edits to the pose (a file's text changed, a
// sample's pose moved from the sample's own, a drag's answer on its way), its pins and its
// targets (work to an animator, though no drag changed the pose yet: a shift-click's pins,
// a drag's targets kept after its solve failed; they used to go unasked). Asked about
// before it gives way (mayReplace, a Sample: solve.js chooseSample).
export function unsaved() {
  const sample = state.samples[state.sample];
  const moved = doc.active
    ? doc.text !== doc.original
    : Boolean(sample && state.committed) && !samePose(state.committed, sample.pose);
  const pose = moved || solver.commitPending;
  return { pose, pins: state.pins.size, targets: state.targets.size };
}

const samePose = (a, b) => Object.keys(b).every((j) => a[j] && a[j].every((v, i) => v === b[j][i]));

// Whether the state shown (the open file, or the sample) has anything to lose (``unsaved``).
export function hasEdits() {
  const { pose, pins, targets } = unsaved();
  return pose || pins > 0 || targets > 0;
}

const counted = (n, word) => `${n} ${word}${n === 1 ? '' : 's'}`;

// What ``unsaved()`` holds, named: "your edits to the pose, 2 pins and 1 target".
export function named({ pose, pins, targets }, edits = 'your edits to the pose') {
  const some = [pose && edits, pins && counted(pins, 'pin'), targets && counted(targets, 'target')]
    .filter(Boolean);
  return some.length > 1 ? `${some.slice(0, -1).join(', ')} and ${some.at(-1)}` : some.join('');
}

// Whether the state shown (the open file, or a sample) may give way to the file ``name``:
// yes unless it has anything to lose (``unsaved``) and the user says no (a Sample asks the
// same: closingQuestion, solve.js sampleQuestion). A sample's own edits, pins and targets
// went unasked, and opening a file clears the undo history: they were lost for good.
export function mayReplace(name) {
  if (!hasEdits()) return true;
  return window.confirm(doc.active ? closingQuestion(`Open ${name}`) : openingQuestion(name));
}

// The question before the file ``name`` replaces a sample with edits: what is lost, named,
// and that Undo cannot bring it back (a file opened starts the undo history anew).
function openingQuestion(name) {
  const sample = state.samples[state.sample];
  const shown = sample ? `"${sample.name}"` : 'the sample';
  return `Open ${name}? This drops ${named(unsaved())} on ${shown} `
    + `(Undo cannot return to ${shown}: a file opened starts the undo history anew).`;
}

// The question before the open file gives way to ``what`` ("Open b.bvh", "Load the sample
// "walk""): what closing it loses, named (``unsaved``), and what Export BVH would keep: the
// edits to the file, not pins or targets (it said "The edits to a.bvh are lost unless
// exported" of a file with one pin and no edit, which no export keeps).
export function closingQuestion(what) {
  const w = unsaved();
  let kept = '';
  if (w.pose && (w.pins || w.targets)) kept = ' (Export BVH keeps the edits, not pins or targets)';
  else if (w.pose) kept = ' unless exported';
  return `${what}? Closing ${doc.name} loses ${named(w, 'your edits to the file')}${kept}.`;
}

// The pins and targets shown, to compare (``replaceable``).
const marks = () => JSON.stringify([[...state.targets], [...state.pins]]);

// What a yes to replacing the state shown covers: the open file with the edits it has now,
// or the sample with its pose, pins and targets as they are now; and a drag's answer on its
// way then (the question named it: "your edits to the pose"), once committed too.
function replaceable() {
  const gesture = { pending: solver.commitPending, step: history.stack[history.index] };
  if (doc.active) return { original: doc.original, text: doc.text, marks: marks(), ...gesture };
  return { sample: state.sample, pose: JSON.stringify(state.committed), marks: marks(), ...gesture };
}

// Whether ``yes`` (``replaceable``'s, or null) still covers the state shown: nothing to
// lose, or no edit since (a sample's too: re-trying a refused file over a sample edited
// since the yes opened it unasked). The answer of a drag on its way at the yes, still on
// its way or committed since (the next undo step), is no newer edit: it landed while the
// file was read, and a units change then asked the same question again.
function stillCovers(yes) {
  if (!hasEdits()) return true; // (nothing to lose)
  if (!yes || yes.marks !== marks()) return false;
  if (yes.pending) {
    const at = solver.commitPending ? history.index : history.index - 1; // (on its way, committed)
    if (history.stack[at] === yes.step) return true;
  }
  if (solver.commitPending) return false;
  if (doc.active) return yes.original === doc.original && yes.text === doc.text;
  return yes.sample === state.sample && yes.pose === JSON.stringify(state.committed);
}

// Whether the state shown is given up already: a file being read that the user said yes to
// opening over it, nothing newer since. Another file picked or dropped, or a Sample chosen,
// meanwhile takes that file's place unasked: it asked the same again, and a "no" kept
// nothing (the file being read opened over it all the same).
export function givenUp() {
  const t = doc.tried;
  return Boolean(ui.reading && t && t.yes) && stillCovers(t.yes);
}

// Whether the file ``name`` (``text``) is the file last tried, refused since, and the yes
// to it still covers the state shown: picked (or dropped) again, it is asked about only
// for newer edits, as a units change re-trying it is (``readAgain``); it was asked about
// again each time. (The file open picked again is asked about: re-opening drops its edits.)
function retried(name, text) {
  const t = doc.tried;
  if (!t || !t.yes || t.name !== name || t.text !== text) return false;
  if (doc.active && doc.name === name && doc.original === text) return false;
  return stillCovers(t.yes);
}

// A file picked or dropped: read, asked about (``mayReplace``) unless the state shown is
// given up already (``givenUp``, ``retried``), and opened. One picked or dropped, or a
// Sample chosen, while its bytes are read takes its place (a large file's take seconds:
// both were asked about, and the first one asked opened after the later choice). A joint
// map the page refuses is said before asking (it asked, then read nothing).
export async function openFile(file) {
  if (!file) return;
  const pick = ++picked;
  let bytes;
  try {
    bytes = new Uint8Array(await file.arrayBuffer());
  } catch (err) {
    if (pick !== picked) return; // (a later choice stands)
    showError(new ApiError(-1, 'Cannot read the file', `${file.name}: ${err.message}`));
    return;
  }
  if (pick !== picked) return; // (a later choice stands)
  if (bytes.length === 0) { // (the service's 422 said "bvh: String should have at least 1 character")
    showError(new ApiError(-1, 'Empty file', `${file.name}: the file is empty (0 bytes); nothing was opened`));
    return;
  }
  const decoded = decodeFile(bytes);
  // lines ended by CR alone (classic Mac OS): read as LF, as the service reads them (an
  // edit then comes back with LF ends); the page's own reader splits at LF
  const crOnly = decoded.text.includes('\r') && !decoded.text.includes('\n');
  const text = crOnly ? decoded.text.replaceAll('\r', '\n') : decoded.text;
  const acclaim = acclaimFile(file.name, text);
  if (acclaim) { // (the service refused it as "not a BVH file (no HIERARCHY keyword)")
    showError(new ApiError(-1, 'Not a BVH file', `${file.name}: ${acclaim}; nothing was opened`));
    return;
  }
  let jointMap;
  try {
    jointMap = mapFor(file.name, text);
  } catch (err) {
    showError(err);
    return;
  }
  if (!givenUp() && !retried(file.name, text) && !mayReplace(file.name)) return;
  const yes = replaceable(); // (re-trying the file after a refusal asks only about newer edits)
  if (doc.active || doc.tried) showSettings(DEFAULT_SETTINGS); // each file read anew (MENUS, above)
  showMap(jointMap);
  await openText(text, file.name, { encoding: decoded.encoding, jointMap, yes });
}

// An Acclaim ASF (skeleton) or AMC (motion) file, by its name or its first keyword, and no
// BVH: why the editor does not open it and what to do instead, or null.
const ACCLAIM = /^(?:#[^\n]*\n|\s)*:(version|name|units|documentation|root|bonedata|fully-specified|degrees)\b/i;

function acclaimFile(name, text) {
  if (/HIERARCHY/i.test(text.slice(0, 65536))) return null;
  const kind = /\.(asf|amc)$/i.exec(name) || ACCLAIM.exec(text.slice(0, 4096));
  if (!kind) return null;
  return 'an Acclaim ASF/AMC file (a skeleton .asf, its motion .amc): the editor reads BVH '
    + 'only. Convert the pair to one BVH file with a motion-capture tool (an ASF/AMC import, '
    + 'then a BVH export: e.g. Blender with an ASF/AMC import add-on, then File > Export > '
    + 'Motion Capture (.bvh)) and open that';
}

// The joint map a file opened from the picker (or a drop) is read with: the field's, for the
// file last asked for opened again; the open file's own, for it; none for another file.
function mapFor(name, text) {
  const t = doc.tried;
  if (t && t.name === name && t.text === text) return readMap();
  if (doc.active && doc.name === name && doc.original === text) return doc.jointMap;
  return null;
}

// "other…" in the Units menu: a number of metres per unit, asked for, listed in the menu
// and chosen (true), or none (false: the menu back to what it showed). The service takes
// any number; the menu listed six units, and a file in none of them (decimetres, a game's
// own scale) could not be opened, though the refusal said "state them ... or a number of
// metres per unit".
export function otherUnits(before = 'auto') {
  const menu = $('bvh-units');
  const was = doc.active ? doc.settings : doc.tried && doc.tried.settings;
  // (cancelled: the file's units, or with no file the choice before, kept for the next one)
  const back = () => { menu.value = was ? was.units : before; };
  const typed = window.prompt('Metres per unit of this file (e.g. 0.1 for decimetres, 0.0254 for inches):', '');
  if (typed === null || typed.trim() === '') {
    back();
    return false;
  }
  const value = Number(typed.trim());
  if (!Number.isFinite(value) || value <= 0) {
    back();
    showError(new ApiError(-1, 'Units', `${typed.trim().slice(0, 20)}: not a number of metres per unit (a positive number: 0.1 for decimetres)`));
    return false;
  }
  const key = String(value);
  if (![...menu.options].some((o) => o.value === key)) {
    const option = document.createElement('option');
    option.value = key;
    option.textContent = `${key} m`;
    menu.insertBefore(option, menu.querySelector('option[value=other]'));
  }
  menu.value = key;
  return true;
}

// Units, up axis or joint map changed: read again the file last asked for, with the joint
// map in the field. If that is the open file, its edits are kept and Reset still returns
// to it as opened (the undo history starts anew: its poses were in the old units); if its
// opening failed, that file, not the open one, asking first if the open file has edits
// newer than the yes to its opening. (After a drag's last answer.)
export function readAgain() {
  whenCommitted(function readNow() {
    if (ui.drag) { // (begun while the drag before was being committed): committed first
      endDrag(true);
      whenCommitted(readNow);
      return;
    }
    const t = doc.tried;
    if (!t) {
      if (!doc.active && $('bvh-map').value.trim()) {
        showError(new ApiError(-1, 'Joint map', 'open a BVH file first: the map is sent with its requests'));
      }
      return;
    }
    const open = doc.active && t.name === doc.name && t.text === doc.original;
    let jointMap;
    try {
      jointMap = readMap();
    } catch (err) {
      if (open && doc.settings) showSettings(doc.settings); // not read again: the menus say how it was
      showError(err);
      return;
    }
    if (open) {
      openText(doc.text, doc.name, { original: doc.original, encoding: doc.encoding, jointMap, again: true });
    } else if (stillCovers(t.yes) || mayReplace(t.name)) {
      // the user said yes to these edits being lost (then, or just now): asked again only
      // if there are newer ones
      openText(t.text, t.name, { encoding: t.encoding, jointMap, yes: replaceable() });
    } else {
      // "no": nothing read; the menus say how the open file was read (over a sample: how
      // the file was last tried; an earlier file's, closed since, said nothing true)
      const was = doc.active ? doc.settings : t.settings;
      if (was) showSettings(was);
    }
  });
}

export function closeFile() {
  doc.active = false;
  doc.followed = null;
  centreFloor(0, 0);
  doc.info = null;
  doc.jointMap = null;
  showMap(null);
  releaseTexts(); // (no file: every one)
  buildSkeleton();
  buildCharacterBones();
  $('bvh-loaded').hidden = true;
  $('export').textContent = 'Export JSON';
  $('export').title = 'Download the pose as JSON';
  $('reset').title = 'Back to the sample pose, no targets, no pins';
  clearHistory();
  doc.tried = null; // closed: a units / up change no longer re-opens it
  showSettings(DEFAULT_SETTINGS); // (they said how the file closed was read)
  controls.target.set(0, 0.85, 0);
  camera.position.set(0.75, 1.3, 2.9);
  controls.update();
}

// Show another frame of the file: its targets go (they were for the other frame), pins stay.
// (after the gesture's last answer, where one is on its way: a scrub dropped it)
// A "No such frame" banner goes with it (the slider's, the box's keys'; it stayed up).
export function setFrame(frame) {
  if (ui.currentError && ui.currentError.title === 'No such frame') clearError();
  $('bvh-frame').value = String(frame); // both controls show the frame asked for meanwhile
  const box = $('bvh-frame-number');
  delete box.dataset.editing;
  box.value = String(frame);
  whenCommitted(() => showFrame(frame));
}

// The frame box: show the frame typed (0-based, as the API's `frame`), or say why not and
// show the frame asked for before.
export function jumpToFrame(typed) {
  const box = $('bvh-frame-number');
  if (!doc.active) return;
  const last = lastFrame(doc.info);
  const raw = String(typed).trim();
  // plain whole numbers only, as the rest of the editor reads them (the box took 1e1 for
  // frame 10: JavaScript's Number, and the number input lets e through)
  const frame = /^\d+$/.test(raw) ? Number(raw) : NaN;
  if (raw === '' || !Number.isInteger(frame) || frame < 0 || frame > last) {
    delete box.dataset.editing;
    box.value = $('bvh-frame').value;
    if (raw !== '') {
      refusedAt = doc.frame;
      showError(new ApiError(-1, 'No such frame', `${doc.name}: frame ${raw.slice(0, 20)}: `
        + `it has frames 0 to ${last} (0-based, as the API's frame)`));
    }
    return;
  }
  setFrame(frame);
}
let refusedAt = -1; // the frame shown when a frame typed was refused (refreshFrame)

function showFrame(frame) {
  if (!doc.active || frame === doc.frame) return;
  endDrag(false);
  cancelSolves();
  doc.frame = frame;
  doc.shown = doc.text;
  state.targets.clear();
  // (the frame's line found by the text's layout, not by walking the text to it)
  const row = committedRow(doc.text, frame, doc.info.frames, channelCount(doc.info));
  state.committed = filePose(doc.text, frame, row);
  state.pose = clonePose(state.committed);
  // not an undo step, and no step changes: undo / redo show the frame of their edit
  refresh();
  const broken = state.committed.pelvis.every(Number.isFinite) ? null : brokenRow(doc.text, frame);
  if (broken) showError(new ApiError(-1, 'Broken frame', broken)); // (refreshFrame clears it)
}

// The view follows the character from frame to frame (its pelvis, along the floor; the
// orbit and zoom kept): a character that walks left the view as the frames were scrubbed,
// the camera staying where the file opened. An edit at the frame shown moves no camera.
function followFrame() {
  const pelvis = state.committed && state.committed.pelvis;
  if (!pelvis || !pelvis.every(Number.isFinite)) return; // (a frame cut short: no pose)
  const was = doc.followed;
  if (was && was.frame !== doc.frame) {
    const d = new THREE.Vector3(pelvis[0] - was.pelvis[0], 0, pelvis[2] - was.pelvis[2]);
    camera.position.add(d);
    controls.target.add(d);
    controls.update();
  }
  doc.followed = { frame: doc.frame, pelvis: [...pelvis] };
  centreFloor(pelvis[0], pelvis[2]);
}

export function refreshFrame() {
  releaseTexts(); // (the texts no longer committed or shown)
  if (!doc.active) return;
  followFrame();
  $('bvh-frame').value = String(doc.frame);
  const box = $('bvh-frame-number');
  if (!box.dataset.editing) box.value = String(doc.frame); // (not what the user is typing)
  const t = doc.frame * doc.info.frame_time;
  $('bvh-frame-label').textContent = `/ ${lastFrame(doc.info)} (${t.toFixed(2)} s)`;
  // a broken frame's banner goes with it (an undo or redo showing another frame too)
  const e = ui.currentError;
  if (e && e.title === 'Broken frame' && !e.detail.includes(`: frame ${doc.frame} holds`)) clearError();
  if (e && e.title === 'No such frame' && doc.frame !== refusedAt) clearError(); // (an undo's frame)
}
