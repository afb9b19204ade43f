// The undo history's steps, and what a step of a file holds: not the file's text (a copy per
// step: a 7.5 MB file of 7,000 frames, 200 steps, up to 1.5 GB in the page), but how it
// differs from the step before: the lines its edit changed (an answer of the service
// rewrites one frame's line). The text of the step shown is held whole (history.text: the
// open file's doc.text, the same string); undo and redo rebuild the text of the step they
// go to from it, line for line, byte for byte. A sample's steps hold its index, no text.

import { history } from './state.js';
import { apply, diff, lineChange } from './textdiff.js';

const MAX_STEPS = 200;

export function clearHistory() {
  history.stack = [];
  history.index = -1;
  history.text = null;
}

// The step shown as a snapshot (solve.js restore): a file's with its text.
export function currentStep() {
  const step = history.stack[history.index];
  return step && 'change' in step ? withText(step) : step;
}

const withText = ({ change, ...step }) => ({ ...step, text: history.text });

// A snapshot (solve.js snapshot) becomes the newest step (the steps after the one shown go).
// ``edit``: how its text was made of the step shown's, where a splice knows it (one frame's
// line rewritten: editor/excerpt.js): the step's change is that line, without reading the
// two texts (``diff`` compares them from each end: 3-4 ms a commit on a 7.5 MB file).
export function pushStep(snap, edit = null) {
  history.stack.length = history.index + 1;
  const { text, ...step } = snap;
  if (text !== undefined) {
    step.change = history.index >= 0 && history.text !== null ? changeOf(history.text, text, edit) : null;
    history.text = text;
  }
  history.stack.push(step);
  if (history.stack.length > MAX_STEPS) {
    history.stack.shift();
    if ('change' in history.stack[0]) history.stack[0].change = null; // (nothing before it now)
  }
  history.index = history.stack.length - 1;
}

function changeOf(a, b, edit) {
  if (!edit || edit.from !== a || edit.to !== b) return diff(a, b);
  return lineChange(edit.start, edit.fromLength - edit.end, edit.before, edit.after);
}

// Undo: the step before becomes the one shown (a snapshot, its text rebuilt), or null.
export function stepBack() {
  if (history.index <= 0) return null;
  const { change } = history.stack[history.index];
  if (change) history.text = apply(history.text, change, false);
  history.index -= 1;
  return currentStep();
}

// Redo: the step after becomes the one shown, or null.
export function stepForward() {
  if (history.index >= history.stack.length - 1) return null;
  history.index += 1;
  const { change } = history.stack[history.index];
  if (change) history.text = apply(history.text, change, true);
  return currentStep();
}

// What the history holds of the file besides the text shown: the characters of its steps'
// changes (the lines they replaced and those they wrote), and the steps.
export function heldSize() {
  let chars = 0;
  for (const step of history.stack) {
    for (const h of (step.change && step.change.hunks) || []) chars += h.from.length + h.to.length;
  }
  return { steps: history.stack.length, chars, text: history.text === null ? 0 : history.text.length };
}
