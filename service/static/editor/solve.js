// Edits, undo history and solving: snapshots (pose, targets, pins; a file's text and frame),
// undo / redo / reset / sample, and the solve requests (editor.js's frame loop sends them).

import { $, doc, history, solver, state, ui } from './state.js';
import {
  aboutServer, api, ApiError, bannerLasts, clearError, onBack, serverDown, showError,
} from './api.js';
import { excerptOf, seedLayout } from './excerpt.js';
import { endDrag } from './interaction.js';
import { currentStep, pushStep, stepBack, stepForward } from './history.js';
import { refresh, updateButtons } from './panel.js';
import {
  cancelOpening, closeFile, closingQuestion, filePose, givenUp, hasEdits, named, toFile, unsaved,
} from './file.js';

// ------------------------------------------------------------------------------------
// Snapshots and undo history; undo, redo, samples, reset
// ------------------------------------------------------------------------------------
export const clonePose = (pose) => Object.fromEntries(Object.entries(pose).map(([k, v]) => [k, [...v]]));

export function snapshot() {
  const snap = {
    pose: clonePose(state.committed),
    targets: [...state.targets].map(([j, p]) => [j, [...p]]),
    pins: [...state.pins],
  };
  if (doc.active) {
    snap.text = doc.text; // (a step keeps only how it differs from the step before: history.js)
    snap.frame = doc.frame;
  } else {
    snap.sample = state.sample; // (its name in the menu and the export, Reset's pose)
  }
  return snap;
}

// Back to a snapshot; a file's at ``frame`` (its own by default): at another frame, the
// frame as the snapshot's text has it, without its targets (they were for its frame).
export function restore(snap, frame = snap.frame) {
  const moved = doc.active && snap.text !== undefined && frame !== snap.frame;
  state.committed = moved ? filePose(snap.text, frame) : clonePose(snap.pose);
  state.pose = clonePose(state.committed);
  state.targets = new Map(moved ? [] : snap.targets.map(([j, p]) => [j, [...p]]));
  state.pins = new Set(snap.pins);
  if (!doc.active && snap.sample !== undefined) {
    state.sample = snap.sample;
    $('sample').value = String(snap.sample);
  }
  if (doc.active && snap.text !== undefined) {
    doc.text = snap.text;
    doc.shown = snap.text;
    doc.frame = frame;
  }
  forgetAnswerText();
}

// A snapshot's or step's state besides its text (a step's keys are not in a snapshot's order).
const parts = (s) => [s.pose, s.targets, s.pins, s.frame, s.sample];

// Whether two texts are the same: by the splice that made ``b`` of ``a`` (``edit``,
// editor/excerpt.js: the line it rewrote), where there is one; else compared (the whole of
// two texts as long: a 7.5 MB file's answer, 2-3 ms, the new one copied whole first).
const sameText = (a, b, edit) => (
  edit && edit.from === a && edit.to === b ? edit.before === edit.after : a === b
);

// The same state (no new undo step): also a step's state scrubbed to another frame (its
// targets gone with the scrub), so a scrub never becomes a step of its own. ``edit``:
// pushHistory's.
function sameSnapshot(a, b, edit) {
  if (!a || !sameText(a.text, b.text, edit)) return false;
  if (a.frame !== b.frame) return b.targets.length === 0 && JSON.stringify(a.pins) === JSON.stringify(b.pins);
  return JSON.stringify(parts(a)) === JSON.stringify(parts(b));
}

// The pose on screen becomes the committed one (solves start from it).
export function commitShown() {
  state.committed = clonePose(state.pose);
  doc.text = doc.shown;
}

// The state shown becomes an undo step (unless it is the step shown). ``edit``: how its
// text was made of the step's, where a splice knows it (sendSolve): then neither text is
// read to compare them or to find what changed (history.js pushStep). ``kept``: a step whose
// targets and pins the new one has (landAgain: those of the edit sent again, not the ones
// shown now, an edit made since among them; a gesture's failed commit during a drag begun
// since: the state that drag began from).
export function pushHistory(edit = null, kept = null) {
  forgetAnswerText(); // (a gesture given up: its answer's text is not the file's)
  const snap = snapshot();
  if (kept) Object.assign(snap, { targets: kept.targets.map(([j, p]) => [j, [...p]]), pins: [...kept.pins] });
  if (sameSnapshot(currentStep(), snap, edit)) {
    updateButtons(); // nothing changed (e.g. an option toggled with no targets)
    return;
  }
  pushStep(snap, edit);
  updateButtons();
}

export function cancelSolves() {
  solver.epoch += 1;
  // the solve in flight is given up: its answer would be dropped, and waiting for it held
  // the next solve back (for good, from a server that never answered)
  if (solver.giveUp) solver.giveUp.abort();
  solver.giveUp = null;
  solver.dirty = false;
  solver.commitPending = false;
  solver.busyTries = 0;
  solver.interrupted = null; // (what an outage interrupted is not shown now: not sent again)
  solver.again = null;
  // the gesture is dropped: what waited for it runs once the action dropping it is done
  const waiting = solver.afterCommit.splice(0);
  if (waiting.length) queueMicrotask(() => waiting.forEach((fn) => fn()));
}

// ``fn`` now, or once the gesture's last answer is committed (or refused, or the gesture
// dropped) where one is on its way: a scrub, an export or a units change made then dropped
// the edit shown, or wrote the file without it. Only for the file it was asked on.
export function whenCommitted(fn) {
  if (!solver.commitPending) {
    fn();
    return;
  }
  const owner = doc.original;
  solver.afterCommit.push(() => {
    if (doc.original === owner) fn();
  });
}

function settled() {
  for (const fn of solver.afterCommit.splice(0)) fn();
}

// Undo and redo show the frame of the edit they undo or redo (a scrub changes no step):
// undo, the step before at the undone edit's frame; redo, the redone step as it was made.
export function undo() {
  if (ui.reading) return; // editing waits for a file's answer (file.js)
  if (solver.commitPending || ui.drag) {
    // a gesture not yet a step (a drag, or its last answer still on the way): undo drops
    // it alone (it also undid the step before); what waited for it goes on
    endDrag(false);
    cancelSolves();
    undoneError(null);
    restore(currentStep(), doc.active ? doc.frame : undefined); // (the frame shown)
    refresh();
    return;
  }
  if (history.index <= 0) return;
  endDrag(false);
  cancelSolves();
  const undone = history.stack[history.index];
  undoneError(undone);
  restore(stepBack(), undone.frame);
  refresh();
}

// A failed solve's banner (a 422, a busy server's 429) goes with the edit it belongs to once
// that is undone: ``step``, the step undone, or null for a gesture dropped before it became
// one. It stayed over the state before the edit, naming a solve of a state no longer shown.
function undoneError(step) {
  const owner = ui.errorOwner;
  if (owner && (step === null ? owner.pending : owner.step === step)) clearError();
}

// The edit a failed solve belongs to (for its banner: undoneError): the gesture still on
// its way, or the step shown (a gesture's last solve failed: its targets, kept, are a step).
const solveOwner = () => ({
  step: history.stack[history.index] || null,
  pending: solver.commitPending || Boolean(ui.drag),
});

export function redo() {
  if (ui.reading || history.index >= history.stack.length - 1) return;
  endDrag(false);
  cancelSolves();
  restore(stepForward());
  refresh();
}

// A sample chosen in the menu: asked first when the state shown has anything to lose (the
// open file's edits, or the sample's own: its pose edited, pins, targets; file.js unsaved;
// a sample's pins and targets went unasked); "no" keeps it all, the menu as it was. Not
// asked again while a file the user said yes to is read over it (file.js givenUp).
export function chooseSample(i) {
  if (hasEdits() && !givenUp() && !window.confirm(sampleQuestion(i))) {
    $('sample').value = doc.active ? '' : String(state.sample);
    return;
  }
  forgetLastSolve();
  loadSample(i);
}

// The panel's "Last solve" was the state given up's: a sample chosen or a file opened says
// none yet (it showed the sample's last solve until the file's first edit). A file read
// again (other units, a joint map) keeps it: the same file, its edits kept.
export function forgetLastSolve() {
  solver.last = null;
}

// The last solve as kept for the panel and the test hook: a file's request without its text
// (the file before the edit: the history holds how the edit changed it). Kept whole, a
// 7.5 MB file was held once more on the page's heap for as long as the answer was the last.
function lastRequest(body, sent) {
  if (body.bvh === undefined) return body;
  const { bvh, ...rest } = body;
  // (the real frame; with an excerpt, how many characters went: editor/excerpt.js)
  return { ...rest, bvh_chars: bvh.length, ...(sent ? { excerpt_chars: sent } : {}) };
}

// A solve's request and answer: a file's frame as an excerpt where it can be
// (editor/excerpt.js; the answer spliced back: the whole file's, byte for byte), else the
// whole file. An answer that is not the excerpt with its frame line rewritten is asked
// again of the whole file (never so far: a guard, not a path).
async function post(body, signal) {
  if (body.bvh === undefined) return api('POST', 'v1/solve', body, { signal });
  const excerpt = excerptOf(body, doc.info);
  if (excerpt) {
    const res = await api('POST', 'v1/bvh/solve', excerpt.body, { signal });
    const spliced = excerpt.splice(res.data);
    if (spliced) {
      const { data, row, edit } = spliced;
      return { ...res, data, row, edit, sentChars: excerpt.body.bvh.length };
    }
  }
  return api('POST', 'v1/bvh/solve', body, { signal });
}

// An answer's text is the file shown while its step is; once undo, redo, Reset or a read
// shows another text, the last solve keeps no copy of it (a 7.5 MB file held once more).
function forgetAnswerText() {
  const response = solver.last && solver.last.response;
  if (response && typeof response.bvh === 'string' && response.bvh !== doc.text && response.bvh !== doc.shown) {
    response.bvh = null;
  }
}

// A sample's question: what is lost, named (a file's: file.js closingQuestion; a sample's
// edits are not: Undo brings back the steps before the sample, only an edit whose answer
// is on its way is dropped).
function sampleQuestion(i) {
  if (doc.active) return closingQuestion(`Load the sample "${state.samples[i].name}"`);
  const shown = state.samples[state.sample].name;
  const as = solver.commitPending ? 'it was before the edit being solved' : 'it is now';
  return `Load the sample "${state.samples[i].name}"? This drops ${named(unsaved())} `
    + `on "${shown}" (Undo returns to "${shown}" as ${as}).`;
}

// Show sample ``i``: no targets, no pins (start-up, Reset, the menu once asked).
export function loadSample(i) {
  endDrag(false);
  cancelSolves();
  cancelOpening();
  if (doc.active) closeFile();
  ui.hovered = null;
  $('hud').hidden = true;
  const pose = state.samples[i].pose;
  replacedError(false);
  restore({ pose, targets: [], pins: [], sample: i });
  pushHistory();
  refresh();
}

export function reset() {
  if (ui.reading) return;
  if (!doc.active) {
    loadSample(state.sample);
    return;
  }
  endDrag(false);
  cancelSolves();
  replacedError(true);
  doc.text = doc.original;
  restore({ pose: filePose(doc.original, doc.frame), targets: [], pins: [], text: doc.original, frame: doc.frame });
  pushHistory();
  refresh();
}

// Reset or a sample loaded replaces the pose shown, and the banner goes with what it was
// about (a failed solve's, a busy server's, a file's closed by the sample, an action's
// refused): it stayed, naming a solve or a file no longer shown (Undo took a failed solve's
// already). A banner about the server or the page stays (api.js aboutServer: the server
// still down, a key needed). ``fileKept``: the open file's Reset, the file as opened shown
// again: what was said of it (cut short, its units, a broken frame) still holds, and stays;
// a failed solve's banner goes.
function replacedError(fileKept) {
  const e = ui.currentError;
  if (!e || aboutServer(e) || (fileKept && !ui.errorOwner)) return;
  clearError();
}

// ------------------------------------------------------------------------------------
// Solving: the request body, throttled requests, answers
// ------------------------------------------------------------------------------------
// The number fields the service bounds, checked in the page: the bounds are the service's
// (service/schemas.py: SolveOptions.tolerance ge=1e-6, le=1.0 m; SolveOptions.soft_ik
// ge=0, le=core.ends.SOFT_IK_MAX = 0.1 m, the field in cm). A value outside (or not a
// number) is refused: the field is marked and says the range, as it is typed (each
// ``input``), and the solves keep the last valid value (``inUse``) until it is mended; it
// was sent as typed, and every solve failed with the service's 422 until then. A value is
// taken when the field is left or Enter pressed (``change``). The fields' min / max are
// set from here. ``empty``: what an emptied field means (soft IK: off), if anything.
const BOUNDS = {
  tolerance: { name: 'Tolerance', min: 1e-6, max: 1, unit: 'm', range: '0.000001 to 1 m' },
  'soft-ik': {
    name: 'Soft IK', min: 0, max: 10, unit: 'cm', range: '0 to 10 cm (0: off)', empty: 0,
  },
};
export const BOUNDED = Object.keys(BOUNDS); // (editor.js checks them on input and change)
const inUse = {}; // field id -> the value the solves send (the field's unit)

// The field ``id``'s value checked, and the field marked (or cleared) so: in range, true,
// and (unless ``typing``: on each keystroke, not yet taken) kept for the solves.
export function checkField(id, { typing = false } = {}) {
  const input = $(id);
  const { name, min, max, unit, range, empty } = BOUNDS[id];
  const blank = input.value === '' && !input.validity.badInput && empty !== undefined;
  const value = blank ? empty : input.valueAsNumber;
  const ok = !input.validity.badInput && value >= min && value <= max; // (NaN: false)
  if (ok && !typing) inUse[id] = value;
  input.setAttribute('aria-invalid', String(!ok));
  const note = $(`${id}-problem`);
  note.textContent = ok ? '' : `${name}: ${range}; the solves use ${inUse[id]} ${unit} until then`;
  note.hidden = ok;
  return ok;
}

// The field ``id`` left (or Enter): its value taken if in range (true; an emptied field
// shows what it means), else refused.
export function takeField(id) {
  const input = $(id);
  const { empty } = BOUNDS[id];
  const emptied = input.value === '' && !input.validity.badInput;
  if (emptied && empty !== undefined) input.value = String(empty);
  return checkField(id);
}

export function setUpFields() {
  for (const [id, { min, max }] of Object.entries(BOUNDS)) {
    // (tolerance: no min, it would be the spinner's step base: 0.001 -> 0.001001)
    if (id !== 'tolerance') $(id).min = String(min);
    $(id).max = String(max);
    inUse[id] = Number($(id).defaultValue); // (the page's default, until a value is checked)
    checkField(id);
  }
}

export function options() {
  const method = document.querySelector('input[name=method]:checked').value;
  const exact = $('exact').checked;
  // unchecked (the networks' raw answer) is sent only where it means something: FABRIK,
  // exact reach and pins keep the bone lengths by construction (the service refuses
  // preserve_bone_lengths: false beside them)
  const pinned = [...state.pins].some((j) => !state.targets.has(j));
  const out = {
    method,
    preserve_bone_lengths: $('preserve').checked || method === 'fabrik' || exact || pinned,
    reach: exact ? 'exact' : 'soft',
    tolerance: inUse.tolerance,
  };
  // the models' own default (GET /v1/models) until the slider is moved
  if ($('carry').dataset.touched) out.carry = $('carry').valueAsNumber;
  if (!$('turn-search').checked) out.turn_search = false; // checked: the models' default
  // soft IK: the field in cm, sent in metres; 0 (off, the service's default) is not sent.
  if (inUse['soft-ik'] !== 0) out.soft_ik = inUse['soft-ik'] / 100;
  return out;
}

function solveBody() {
  if (doc.active) {
    return {
      bvh: doc.text,
      frame: doc.frame,
      units: doc.info.units,
      up: doc.info.up,
      ...(doc.settings.root === 'add' ? { root_position: 'add' } : {}),
      targets: [...state.targets].map(([joint, p]) => ({ joint, position: toFile(p), weight: 1.0 })),
      pins: [...state.pins].filter((j) => !state.targets.has(j)),
      options: options(),
      ...(doc.jointMap ? { joint_map: doc.jointMap } : {}),
    };
  }
  return {
    pose: state.committed,
    targets: [...state.targets].map(([joint, position]) => ({ joint, position, weight: 1.0 })),
    pins: [...state.pins].filter((j) => !state.targets.has(j)),
    options: options(),
  };
}

// An edit happened: solve it on the next frame (commit = it ends a gesture).
export function requestSolve(commit) {
  solver.again = null; // (a new edit: its answer is committed as its own step)
  if (commit) solver.commitPending = true;
  if (state.targets.size === 0) {
    // Nothing to reach: the committed pose stands.
    solver.dirty = false;
    state.pose = clonePose(state.committed);
    doc.shown = doc.text;
    if (solver.commitPending) {
      solver.commitPending = false;
      pushHistory();
    }
    refresh();
    settled();
    return;
  }
  solver.dirty = true;
}

// How many times a gesture's last solve is sent to a busy server (429 or 503 with
// Retry-After, each waited for) before it is given up: at most 4 x 30 s.
export const BUSY_TRIES = 4;

// A gesture's last solve that found no server (unreachable, not answering: status 0) keeps
// its targets, the pose as before it (below); once the server is back (api.js onBack), that
// edit is sent again, once, and its answer committed as the gesture's would have been: in
// place of the step its kept targets made. Not when anything has changed since: an undo,
// Reset, a sample, a file opened or a frame scrubbed (cancelSolves), a drag or another edit
// on its way, a file being read. The kept targets stayed unsolved, the user to drag again.
// Not sent for something under way (a joint pressed, a drag, a solve, a file read), the
// edit still shown: said, as the outage's banner goes (api.js back): it went, the status
// "connected", the kept targets unsolved without a word (a joint pressed as the server was
// found back). It stays until an edit is solved (the drag under way, let go: its answer,
// which carries the kept targets, committed; not its answers on the way, which an Escape
// drops) or the user moves on (an undo of it, Reset, a sample).
// What an edit not applied leaves, and the edit sent again once the server was back (the
// banners' words).
const KEPT = '(the pose is as before it, its targets kept: drag again to retry)';
const SENT_AGAIN = 'the edit, sent again once the server was back,';

function sendAgain() {
  const kept = solver.interrupted;
  solver.interrupted = null;
  if (!kept || kept.epoch !== solver.epoch || history.stack[history.index] !== kept.step) return;
  if (state.targets.size === 0) return;
  if (ui.drag || ui.reading || solver.commitPending || solver.dirty || solver.inflight) {
    const why = 'the server is back, but the edit its outage interrupted was not sent again '
      + `(something else was under way): it is not applied ${KEPT}`;
    showError(new ApiError(0, 'Edit not applied', why), { step: kept.step, pending: false, lasting: true });
    return;
  }
  solver.again = kept;
  solver.commitPending = true;
  solver.dirty = true; // (editor.js's frame loop sends it)
}
onBack(sendAgain);

// Two solves' requests the same (a file's text compared by reference: the same string).
const sameRequest = (a, b) => a.bvh === b.bvh && JSON.stringify({ ...a, bvh: 0 }) === JSON.stringify({ ...b, bvh: 0 });

// The edit sent again (sendAgain) answered while the user had begun another since it went
// (a value typed, a joint pressed or dragged: solver.dirty, ui.drag): it lands as it does
// alone, the interrupted gesture's one step in place of the one its kept targets made (the
// answer's pose and text, those targets and pins), and the new edit goes on from it, a step
// of its own. Its answer waited for the new edit's, the two one step over the kept,
// unsolved one (undone, the drag as if never solved). ``edit``: the answer's splice, if
// any. A press's re-ask of the state sent (interaction.js endDrag: a click) is dropped:
// that state is the step now, solved.
function landAgain(again, body, edit) {
  const same = !ui.drag && sameRequest(body, solveBody()); // (before the commit: the pose sent)
  const spliced = edit && edit.from === doc.text ? edit : null;
  commitShown();
  solver.again = null;
  if (spliced) seedLayout(spliced);
  if (again.replace) stepBack();
  pushHistory(spliced, again.step);
  // a press or drag begun on the kept step: Escape goes back to this one (not the unsolved)
  if (ui.drag) ui.drag.before = currentStep();
  if (same || (ui.drag && !solver.dirty)) {
    solver.dirty = false; // (nothing new to send: the press's gesture, if any, asks its own)
    solver.commitPending = false;
  }
}

const withNote = (err, note, title = err.title) => new ApiError(
  err.status, title, `${err.detail}; ${note}`, err.requestId, err.retryAfter,
);

export async function sendSolve() {
  solver.dirty = false;
  solver.inflight = true;
  const epoch = solver.epoch;
  const commit = solver.commitPending;
  const again = commit ? solver.again : null; // (sendAgain: the edit an outage interrupted)
  let settle = false; // the gesture's answer is in: run what waited for it
  const body = solveBody();
  solver.sent += 1;
  $('solve-count').textContent = String(solver.sent);
  const giveUp = new AbortController(); // (cancelSolves)
  solver.giveUp = giveUp;
  try {
    const res = await post(body, giveUp.signal);
    if (epoch !== solver.epoch) return; // undone / reset / scrubbed meanwhile
    solver.answered += 1;
    solver.busyTries = 0;
    if (body.bvh === undefined) {
      state.pose = res.data.pose;
    } else {
      doc.shown = res.data.bvh;
      state.pose = filePose(doc.shown, body.frame, res.row); // (the frame's values, where the splice knows them)
    }
    state.model = res.data.model;
    const server = parseFloat(res.serverTime);
    solver.latencies.push(server);
    if (solver.latencies.length > 50) solver.latencies.shift();
    solver.last = {
      request: lastRequest(body, res.sentChars),
      response: res.data, // (a file's: its bvh is the text shown now, not a copy; forgetAnswerText)
      serverTime: res.serverTime,
      serverMs: server,
      rttMs: res.rtt,
      requestId: res.requestId,
    };
    // A lasting banner (an edit sent again, or not sent, not applied: api.js ``back``) goes
    // once an edit is solved, its answer committed; not with an answer on its way (a drag's,
    // not let go: an Escape drops it, the kept targets still unsolved). It went with a drag's
    // first answer as the server was found back, unseen: an Escape then, and the edit stayed
    // unsolved without a word.
    const lastingBanner = bannerLasts();
    let solved = false;
    if (!lastingBanner) clearError();
    if (commit && again && history.stack[history.index] === again.step && (solver.dirty || ui.drag)) {
      landAgain(again, body, res.edit);
      solved = true;
    } else if (commit && !solver.dirty && solver.commitPending && !ui.drag) {
      // (the splice that made the answer's text, of the committed one: the commit reads
      // neither whole, for the next solve's excerpt nor for the undo step; editor/excerpt.js)
      const edit = res.edit && res.edit.from === doc.text ? res.edit : null;
      commitShown();
      solver.commitPending = false;
      solver.again = null;
      if (edit) seedLayout(edit);
      // the edit sent again: its answer takes the place of the step its kept targets made
      if (again && again.replace && history.stack[history.index] === again.step) stepBack();
      pushHistory(edit);
      solved = true;
    }
    if (lastingBanner && solved) clearError();
    refresh();
    settle = !solver.commitPending;
  } catch (err) {
    if (epoch !== solver.epoch) return;
    let said = err;
    let lasting = false; // (its banner outlives the outage: api.js back)
    const wait = err.retryAfter ? Math.min(err.retryAfter, 30) : 0;
    if (wait) {
      // a busy server (429, 503) says when to come back: no solve goes before (capped at
      // 30 s); the drag's latest targets go then. It was asked again at each pointer move,
      // each answered 429 at once (with a file, the whole file uploaded each time).
      solver.holdUntil = performance.now() + wait * 1000;
    }
    // (the edit sent again to a server back but still loading its models, 503 and
    // Retry-After, as each start answers until ready: it waits for them, its tries not
    // counted; models that fail to load answer without Retry-After, and it is given up)
    const loading = again && wait && err.status === 503 && err.title === 'Models not ready';
    if (commit && !solver.dirty && loading) {
      solver.dirty = true;
      said = withNote(err, `the edit is sent again in ${wait} s`);
    } else if (commit && !solver.dirty && wait && solver.busyTries < BUSY_TRIES - 1) {
      // The gesture's final solve refused by a busy server: sent again once its Retry-After
      // is over (the gesture still on its way: what waits for it waits on), BUSY_TRIES
      // times in all. It snapped back, the targets kept, and nothing was sent again.
      solver.busyTries += 1;
      solver.dirty = true;
      said = withNote(err, `the edit is sent again in ${wait} s (try ${solver.busyTries + 1} of ${BUSY_TRIES})`);
    } else if (commit && !solver.dirty) {
      // The gesture's final solve failed: keep its targets (so it can be retried) but not
      // a pose the server never produced, nor one of the drag's answers: the screen shows
      // the pose as it was, the one Export writes and the next solve starts from. A drag
      // begun since (its solves went as this gesture's: commitPending) is not part of it:
      // the step is the state as it was pressed (``before``); it was the drag's targets
      // then, a step mid-drag, and its release made another (an undo went back to a point
      // of the drag never let go).
      solver.commitPending = false;
      state.pose = clonePose(state.committed);
      doc.shown = doc.text;
      const shown = history.stack[history.index];
      pushHistory(null, ui.drag && ui.drag.moved ? ui.drag.before : null);
      const step = history.stack[history.index];
      solver.again = null;
      if (wait) {
        said = withNote(err, `still busy after ${BUSY_TRIES} tries: the edit is not applied ${KEPT}`);
      } else if (again && err.status === 0) {
        // (it stays once the server is back, as it still holds: api.js back; until an edit
        // is solved, or the user moves on: an undo, Reset, a sample). Titled for the edit,
        // not the server: it said "Server unreachable" under the status "connected" then.
        lasting = true;
        said = withNote(err, `${SENT_AGAIN} failed again: it is not applied ${KEPT}`, 'Edit failed again');
      } else if (again && err.status >= 400) {
        // The edit sent again answered with the server's error (a 500; a 4xx, refused): its
        // title and detail, and what it means for the edit, as for one that failed again (a
        // lasting banner, not sent a third time). It said only the server's error.
        lasting = true;
        const how = err.status >= 500 ? 'failed on the server' : 'was refused by the server';
        said = withNote(err, `${SENT_AGAIN} ${how}: it is not applied ${KEPT}`);
      } else if (err.status === 0) {
        // (the same step kept again, an option changed meanwhile: still the step to replace)
        const before = solver.interrupted;
        const replace = step !== shown
          || Boolean(before && before.epoch === solver.epoch && before.step === step && before.replace);
        solver.interrupted = { epoch: solver.epoch, step, replace };
        said = withNote(err, 'the edit is sent again once the server is back');
        if (!serverDown()) queueMicrotask(sendAgain); // (an answer came meanwhile)
      }
      solver.busyTries = 0;
    }
    showError(said, { ...solveOwner(), lasting });
    refresh();
    settle = !solver.commitPending;
  } finally {
    solver.inflight = false;
    if (solver.giveUp === giveUp) solver.giveUp = null;
    if (settle) settled(); // (outside the try: what waited is not a solve that failed)
  }
}
