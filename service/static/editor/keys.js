// Editing a joint without the mouse: the joint selected (the panel's picker, [ and ] in the
// view, or a click on it), its target typed in metres (x, y, z), nudged with the keys, its pin
// toggled (P) and its target removed (Delete).
//
// The view's canvas takes the focus (Tab reaches it first; a joint pressed gives it the
// focus too), and its keys are read only while it has it: a panel field typed in keeps its
// own keys. Ctrl+Z / Ctrl+Y and Escape stay the page's (editor.js).
//
// A nudge moves the selected joint's target (from where the joint stands when it has none)
// along a world axis by the nudge step (nudge.js: which axis, which step). Nudges are a
// gesture as a drag is (ui.drag, with `keys`): solved as a drag's moves are (throttled,
// from the committed pose), the pin dropped as a drag drops it, Escape cancelling it. The
// gesture ends when the last nudge key is released (or the view loses the focus, another
// joint is selected, the mouse grabs one): one key press is one undo step, a held key's
// repeats and keys held together included (a press made before the last one's answer came
// joins its step).

import * as THREE from 'three';
import { $, pointerDrag, solver, state, ui } from './state.js';
import { requestSolve, snapshot } from './solve.js';
import { camera, drawPose, renderer } from './scene.js';
import { endDrag, removeTarget, togglePin } from './interaction.js';
import { refresh, refreshPanel } from './panel.js';
import { NUDGE_KEYS, nudgeDirection, nudgeStep } from './nudge.js';

const AXES = ['x', 'y', 'z'];
const MAX_METRES = 10000; // a coordinate the service takes at most (schemas.py MAX_COORDINATE)
const held = new Set(); // the nudge keys down (the gesture ends when none is)

const fmt = (v) => v.toFixed(3);
const finite = (p) => Boolean(p) && p.every(Number.isFinite);

// ------------------------------------------------------------------------------------
// Selection
// ------------------------------------------------------------------------------------
// ``joint`` (or null) selected: drawn with its ring, shown in the panel.
export function select(joint) {
  if (joint === ui.selected) return;
  endBurst();
  ui.selected = joint && state.joints.includes(joint) ? joint : null;
  drawPose();
  refreshPanel(); // (the picker, the fields, the targets table's row)
}

// The next (+1) or previous (-1) joint, in the skeleton's order, round the end.
function cycle(by) {
  const n = state.joints.length;
  const i = state.joints.indexOf(ui.selected);
  select(state.joints[i < 0 ? (by > 0 ? 0 : n - 1) : (i + by + n) % n]);
}

// ------------------------------------------------------------------------------------
// Nudges
// ------------------------------------------------------------------------------------
// The world direction of a nudge key, seen from the camera (nudge.js).
function direction(key) {
  const q = camera.quaternion;
  const along = (x, y, z) => new THREE.Vector3(x, y, z).applyQuaternion(q).toArray();
  return nudgeDirection(key, along(1, 0, 0), along(0, 0, -1), along(0, 1, 0));
}

// Where the selected joint's target is, or the joint itself when it has none.
const targetOrJoint = (joint) => state.targets.get(joint) || (state.pose && state.pose[joint]);

// The selected joint and where its target is, with a key gesture begun (or going on), or
// null: no joint, a file being read, a mouse drag (its own), a frame cut short (no pose),
// a key still held after Escape (no new gesture). A nudged joint follows its target, not
// its pin (as dragged).
function burst(ev) {
  const joint = ui.selected;
  if (!joint || ui.reading || pointerDrag()) return null;
  const from = targetOrJoint(joint);
  if (!finite(from)) return null;
  if (!ui.drag) {
    if (ev.repeat) return null;
    ui.drag = { joint, keys: true, moved: true, before: snapshot() };
    state.pins.delete(joint);
  }
  return { joint, from };
}

// The gesture's target moved to ``p``: solved (throttled, as a drag's moves) and drawn.
function moveTarget(joint, p) {
  state.targets.set(joint, p);
  requestSolve(false);
  refreshPanel();
  drawPose();
}

// A nudge's step (m): the Nudge step, Shift 10 times more, Alt a tenth (nudge.js).
const stepOf = (ev) => nudgeStep(Number($('nudge-step').value), ev);

function nudge(key, ev) {
  const at = burst(ev);
  if (!at) return;
  const step = stepOf(ev);
  const d = direction(key);
  moveTarget(at.joint, at.from.map((v, i) => v + d[i] * step));
}

// The nudge gesture ends: committed (its last answer becomes one undo step).
function endBurst() {
  held.clear();
  if (ui.drag && ui.drag.keys) endDrag(true);
}

// ------------------------------------------------------------------------------------
// The view's keys
// ------------------------------------------------------------------------------------
function onKeyDown(ev) {
  if (ev.ctrlKey || ev.metaKey) return; // (Ctrl+Z, Ctrl+Y: editor.js; the browser's own)
  const key = ev.key;
  if (NUDGE_KEYS.includes(key)) {
    ev.preventDefault(); // (no scrolling; Alt+Left: not the browser's Back)
    if (!ui.selected) return;
    held.add(key);
    nudge(key, ev);
  } else if (key === ']' || key === '[') {
    ev.preventDefault();
    cycle(key === ']' ? 1 : -1);
  } else if (key === 'p' || key === 'P') {
    ev.preventDefault();
    pinSelected();
  } else if (key === 'Delete' || key === 'Backspace') {
    ev.preventDefault();
    unsetSelected();
  }
}

function onKeyUp(ev) {
  if (!held.delete(ev.key)) return;
  if (held.size === 0) endBurst();
}

// P and Delete do nothing while the mouse drags (the drag is the joint's edit until it is
// released): the drag went on after them, P's pin on a joint it targeted again (pinned and
// targeted at once), Delete's removed target back at the next move, a step of its own.
function pinSelected() {
  const joint = ui.selected;
  if (!joint || ui.reading || pointerDrag()) return;
  endBurst();
  togglePin(joint);
}

function unsetSelected() {
  const joint = ui.selected;
  if (!joint || ui.reading || pointerDrag() || !state.targets.has(joint)) return;
  endBurst();
  removeTarget(joint);
}

// ------------------------------------------------------------------------------------
// The panel's part: the picker, x / y / z, pin and remove
// ------------------------------------------------------------------------------------
// A coordinate typed (Enter, or the field left): the target there, its other coordinates
// kept exactly (the target's, or the joint's where it has none: not the fields' rounding);
// one edit, one undo step. Not a number, or out of the service's range: refused (the field
// marked, its line saying so), nothing sent; the field keeps the text until it is left
// (Escape: at once), then shows the target again.
function typed(axis) {
  const input = $(`joint-${AXES[axis]}`);
  const joint = ui.selected;
  const from = joint && targetOrJoint(joint);
  const value = input.valueAsNumber;
  const ok = Number.isFinite(value) && Math.abs(value) <= MAX_METRES;
  input.setAttribute('aria-invalid', String(!ok));
  const note = $('joint-xyz-problem');
  note.hidden = ok;
  note.textContent = ok ? '' : `${AXES[axis]}: a number of metres (-${MAX_METRES} to ${MAX_METRES}); nothing was sent`;
  if (!ok) return; // (still being typed: dataset.editing kept)
  delete input.dataset.editing;
  if (ui.reading || !finite(from)) return;
  endBurst();
  const next = [...from];
  next[axis] = value;
  state.pins.delete(joint); // (as a drag or a nudge: the joint follows its target)
  state.targets.set(joint, next);
  requestSolve(true);
  refresh();
}

// A field's own ↑ / ↓: the target moved up or down its axis by a nudge's step (stepOf: the
// Nudge step, Shift 10 times more, Alt a tenth, as the view's keys), as a nudge is (a
// gesture: one undo step per press, a held arrow's repeats and all). The field's native
// step made each repeat a change of its own (a held arrow filled the history with one step
// per repeat, 30 a second), and was a mm whatever Shift or Alt said. From the target's
// coordinate exactly (not the field's mm), or from a value being typed; one not a number
// yet: the field's own.
function fieldArrow(axis, ev) {
  const input = $(`joint-${AXES[axis]}`);
  if (ev.ctrlKey || ev.metaKey || !Number.isFinite(input.valueAsNumber)) return;
  ev.preventDefault(); // (no native step, no change event)
  const typing = input.dataset.editing ? input.valueAsNumber : null;
  const from = ui.selected && targetOrJoint(ui.selected);
  const value = (typing ?? (from ? from[axis] : NaN)) + stepOf(ev) * (ev.key === 'ArrowUp' ? 1 : -1);
  if (!(Math.abs(value) <= MAX_METRES)) return; // (before a gesture begins: it drops the pin)
  const at = burst(ev);
  if (!at) return;
  held.add(ev.key);
  const next = [...at.from];
  next[axis] = value;
  delete input.dataset.editing;
  input.setAttribute('aria-invalid', 'false');
  $('joint-xyz-problem').hidden = true;
  moveTarget(at.joint, next);
}

// A joint's target as the last solve left it: `target reached`, `target 12.3 mm off`, or
// `target` (not solved yet); '' without one.
function targetText(joint) {
  if (!state.targets.has(joint)) return '';
  const last = solver.last && solver.last.response.targets.find((t) => t.joint === joint);
  if (!last) return 'target';
  return last.reached ? 'target reached' : `target ${(last.error * 1000).toFixed(1)} mm off`;
}

// A joint's target in its menu choice: `reached`, `12.3 mm off`, `target` (not solved yet).
function menuText(joint) {
  const text = targetText(joint);
  return text === 'target' ? text : text.replace(/^target /, '');
}

function stateText(joint) {
  if (!joint) return 'none selected';
  const parts = [joint];
  if (state.pins.has(joint)) parts.push('pinned');
  parts.push(targetText(joint) || 'no target: the fields show where it is');
  return parts.join(', ');
}

// The state line, shown as the state is, and said (#joint-said, aria-live: read out when
// it changes) once per gesture: while a drag or a nudge burst goes on, and until its last
// answer is committed, the selected joint's spoken line waits (in soft reach each answer
// changed its "N mm off", and a held key had a screen reader announce 30 lines a second).
// Another joint selected is said at once.
function announce(joint, text) {
  const line = $('joint-state');
  if (line.textContent !== text) line.textContent = text;
  const said = $('joint-said');
  if (said.textContent === text) return;
  const gesture = Boolean(ui.drag) || solver.commitPending;
  if (gesture && said.dataset.joint === (joint || '')) return;
  said.textContent = text;
  said.dataset.joint = joint || '';
}

// The picker, fields and buttons as the state is (panel.js refreshPanel calls it).
export function refreshJoint() {
  const pick = $('joint-pick');
  if (pick.options.length !== state.joints.length + 1) {
    pick.replaceChildren(new Option('(none)', ''), ...state.joints.map((j) => new Option(j, j)));
  }
  // (each choice says its target without the word: "right_shoulder (target reached,
  // pinned)" took 263 px of the menu's 237 in DejaVu Sans, Debian's default font, and was cut)
  for (const option of [...pick.options].slice(1)) {
    const j = option.value;
    const marks = [menuText(j), state.pins.has(j) ? 'pinned' : ''].filter(Boolean);
    const text = marks.length ? `${j} (${marks.join(', ')})` : j;
    if (option.textContent !== text) option.textContent = text;
  }
  pick.value = ui.selected || '';
  const joint = ui.selected;
  announce(joint, stateText(joint));
  const at = joint ? targetOrJoint(joint) : null;
  const editable = Boolean(joint) && !ui.reading && finite(at);
  $('joint-target').disabled = !editable;
  $('joint-target').querySelector('legend').textContent = joint && state.targets.has(joint)
    ? 'Target (m)' : 'Target (m): the joint now';
  let marked = false;
  AXES.forEach((a, i) => {
    const input = $(`joint-${a}`);
    if (input.dataset.editing && document.activeElement === input) { // (being typed in)
      marked ||= input.getAttribute('aria-invalid') === 'true';
      return;
    }
    delete input.dataset.editing;
    input.value = editable ? fmt(at[i]) : '';
    input.setAttribute('aria-invalid', 'false');
  });
  $('joint-xyz-problem').hidden = !marked;
  const pin = $('joint-pin');
  const pinned = Boolean(joint) && state.pins.has(joint);
  pin.disabled = !joint || Boolean(ui.reading);
  pin.setAttribute('aria-pressed', String(pinned));
  pin.textContent = pinned ? 'Unpin' : 'Pin';
  $('joint-unset').disabled = !joint || Boolean(ui.reading) || !state.targets.has(joint);
}

export function wireKeys() {
  const view = renderer.domElement;
  view.tabIndex = 0; // (first in the page's Tab order: the view comes before the panel)
  view.setAttribute('role', 'application'); // (its keys are its own, not a screen reader's)
  view.setAttribute('aria-roledescription', '3D pose view');
  view.setAttribute('aria-label', 'Pose view: joints, targets and pins');
  view.setAttribute('aria-describedby', 'joint-state view-keys');
  view.setAttribute('aria-keyshortcuts', '[ ] ArrowLeft ArrowRight ArrowUp ArrowDown PageUp PageDown P Delete');
  view.addEventListener('keydown', onKeyDown);
  view.addEventListener('keyup', onKeyUp);
  view.addEventListener('blur', endBurst);
  $('joint-pick').addEventListener('change', (ev) => select(ev.target.value || null));
  AXES.forEach((a, i) => {
    const input = $(`joint-${a}`);
    input.addEventListener('input', () => { input.dataset.editing = '1'; });
    input.addEventListener('change', () => typed(i));
    input.addEventListener('keydown', (ev) => {
      if (ev.key === 'Escape') { // back to the value shown, nothing sent
        delete input.dataset.editing;
        refreshJoint();
      } else if (ev.key === 'ArrowUp' || ev.key === 'ArrowDown') {
        fieldArrow(i, ev);
      }
    });
    input.addEventListener('keyup', onKeyUp); // (a held arrow released: its step ends)
    input.addEventListener('blur', () => { // (a refused value: back, unmarked)
      endBurst();
      refreshJoint();
    });
  });
  $('joint-pin').addEventListener('click', pinSelected);
  $('joint-unset').addEventListener('click', unsetSelected);
  refreshJoint();
}
