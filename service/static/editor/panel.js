// The side panel (last solve, targets, pins, buttons) and export (JSON, or the edited BVH).

import { $, doc, history, solver, state, ui } from './state.js';
import { clonePose, options, whenCommitted } from './solve.js';
import { drawPose } from './scene.js';
import { rehover, removeTarget } from './interaction.js';
import { encodeFile, refreshFrame } from './file.js';
import { refreshJoint } from './keys.js';

// ------------------------------------------------------------------------------------
// Panel
// ------------------------------------------------------------------------------------
function fmtMm(m) {
  return `${(m * 1000).toFixed(1)} mm`;
}

export function refreshPanel() {
  const last = solver.last;
  const byJoint = new Map((last ? last.response.targets : []).map((t) => [t.joint, t]));
  const tbody = $('targets').querySelector('tbody');
  tbody.replaceChildren();
  for (const joint of state.targets.keys()) {
    const tr = document.createElement('tr');
    tr.dataset.joint = joint;
    if (joint === ui.selected) tr.className = 'selected'; // (keys.js)
    const result = byJoint.get(joint);
    const cells = [
      [joint, ''],
      [result ? fmtMm(result.error) : '–', 'err'],
      [result ? (result.reached ? '✓' : '✗') : '', result ? (result.reached ? 'ok' : 'miss') : ''],
    ];
    for (const [text, cls] of cells) {
      const td = document.createElement('td');
      td.textContent = text;
      if (cls) td.className = cls;
      tr.appendChild(td);
    }
    const td = document.createElement('td');
    const btn = document.createElement('button');
    btn.type = 'button';
    btn.textContent = '×';
    btn.title = `Remove the target of ${joint}`;
    btn.disabled = Boolean(ui.reading);
    btn.addEventListener('click', () => removeTarget(joint));
    td.appendChild(btn);
    tr.appendChild(td);
    tbody.appendChild(tr);
  }
  $('no-targets').hidden = state.targets.size > 0;
  $('pins').textContent = state.pins.size ? [...state.pins].join(', ') : 'none';
  if (!last) { // none yet on the file or sample shown (file.js showOpened, solve.js chooseSample)
    for (const id of ['latency', 'rtt', 'solve-method', 'solvers', 'bone-error']) $(id).textContent = '–';
    $('latency').title = 'No solve yet on the file or sample shown';
  } else {
    const med = [...solver.latencies].sort((a, b) => a - b)[Math.floor(solver.latencies.length / 2)];
    $('latency').textContent = `${last.serverMs.toFixed(2)} ms (median ${med.toFixed(2)})`;
    $('latency').title = 'X-Total-Time of the last solve (the server, arrival to answer); median of the last 50';
    $('rtt').textContent = `${last.rttMs.toFixed(1)} ms`;
    const r = last.response;
    $('solve-method').textContent = r.iterations ? `${r.method}, ${r.iterations} FABRIK it.` : r.method;
    $('solvers').textContent = r.solvers.join(' → ') || '–';
    $('bone-error').textContent = r.max_bone_length_error === undefined
      ? 'the file\'s own' // BVH: rotations only, offsets untouched
      : `${(r.max_bone_length_error * 100).toPrecision(2)} %`;
  }
  $('model').textContent = `model: ${state.model || '–'}`;
  updateButtons();
  refreshJoint();
  for (const menu of document.querySelectorAll('#panel select')) titleMenu(menu);
}

// A menu's tooltip: the choice shown, whole (one longer than the menu is cut there, with an
// ellipsis: editor.css), with the option's own note (a sample's clip and frame), then what
// the menu is for (its title in the page). A sample's name was cut at the menu's 170 px with
// no way to read it but opening the menu. (editor.js calls it as a menu changes, too.)
export function titleMenu(menu) {
  if (menu.dataset.about === undefined) menu.dataset.about = menu.title;
  const shown = menu.selectedOptions[0];
  const choice = shown ? [shown.textContent, shown.title].filter(Boolean).join(': ') : '';
  const title = [choice, menu.dataset.about].filter(Boolean).join('\n');
  if (menu.title !== title) menu.title = title;
}

export function updateButtons() {
  const reading = Boolean(ui.reading); // editing waits for a file's answer (file.js)
  $('undo').disabled = reading || history.index <= 0;
  $('redo').disabled = reading || history.index >= history.stack.length - 1;
  $('reset').disabled = reading;
  $('clear-targets').disabled = reading || state.targets.size === 0;
}

export function refresh() {
  drawPose();
  refreshPanel();
  refreshFrame();
  rehover(); // (the hover label: the joint under a still pointer now)
}

export function exportDocument() {
  if (doc.active) {
    return { format: 'bvh', name: exportName(), frame: doc.frame, bvh: doc.text };
  }
  return {
    format: 'marionette-pose',
    version: 1,
    frame: { units: 'metres', up: '+Y', forward: '+Z', left: '+X' },
    pose: clonePose(state.pose),
    targets: [...state.targets].map(([joint, position]) => ({ joint, position: [...position] })),
    pins: [...state.pins],
    options: options(),
    model: state.model,
    sample: state.samples[state.sample] ? state.samples[state.sample].name : null,
  };
}

function exportName() {
  return `${doc.name.replace(/\.bvh$/i, '')}-edited.bvh`;
}

// (after the gesture's last answer, where one is on its way: the export left it out)
export function exportPose() {
  whenCommitted(writeExport);
}

function writeExport() {
  const blob = doc.active
    ? new Blob([encodeFile(doc.text, doc.encoding)], { type: 'text/plain' })
    : new Blob([JSON.stringify(exportDocument(), null, 2)], { type: 'application/json' });
  const url = URL.createObjectURL(blob);
  const a = document.createElement('a');
  a.href = url;
  a.download = doc.active ? exportName() : 'marionette-pose.json';
  document.body.appendChild(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(url), 1000);
}
