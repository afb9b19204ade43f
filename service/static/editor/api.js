// The editor's API helper and error banner: every request to the service goes through api();
// failures (application/problem+json, or no answer at all) become ApiError and are shown.

import { $, ui } from './state.js';

// ------------------------------------------------------------------------------------
// API helper: every call goes through here; failures become ApiError and are shown.
// ------------------------------------------------------------------------------------
export class ApiError extends Error {
  constructor(status, title, detail, requestId = null, retryAfter = null) {
    super(`${title}: ${detail}`);
    this.status = status;
    this.title = title;
    this.detail = detail;
    this.requestId = requestId;
    this.retryAfter = retryAfter; // seconds (a 429's or 503's Retry-After), or null
  }
}

function apiKey() {
  return $('api-key').value.trim();
}

// How long a request may go unanswered before it is given up (ms): a solve or a read the
// server never answers (stalled, or a connection held open by a proxy) held the one solve
// in flight for good, and every later drag sent nothing, without a word. The service
// answers within its deadline (2 s by default, POSE_DEADLINE), a file's upload aside.
export const NO_ANSWER_MS = 60_000;
const NOT_ANSWERING = 'server not answering';
const DOWN = ['server unreachable', NOT_ANSWERING];

// The status says the server is down (unreachable, not answering): it said so until the
// page's next request, a restarted server's too. While it says so, the server's liveness
// (GET v2/health/live: no body, no model, no key) is asked every WATCH_MS, and the status
// says "connected" once it answers (``back``).
export const WATCH_MS = 3000;
let watching = false;

function down(text) {
  $('status').textContent = text;
  if (watching) return;
  watching = true;
  setTimeout(watch, WATCH_MS);
}

async function watch() {
  if (!DOWN.includes($('status').textContent)) {
    watching = false; // (an answer came meanwhile)
    return;
  }
  try {
    await fetch('v2/health/live', { cache: 'no-store', signal: AbortSignal.timeout(WATCH_MS) });
  } catch {
    setTimeout(watch, WATCH_MS);
    return;
  }
  watching = false;
  back();
}

// The server answered (a request's answer, or its liveness): the status says "connected"
// where it said it was down, and the banner that said so goes (a request's that could not
// reach the server, or that it did not answer: status 0). It stayed up, under "connected",
// until the next solve landed or it was dismissed. Not a banner that outlives the outage
// (``lasting``: solve.js, an edit sent again that failed again, or that the server failed,
// not sent a third time; one not sent again, something under way): what it says, the edit
// not applied, still holds; it went, and the page said "connected", no error, the edit
// never solved. It goes once an edit is solved, its answer committed (solve.js sendSolve),
// or with the edit undone, Reset, a sample, ×. Then, where it said it was down, what waits
// for the server runs (``onBack``: solve.js sends again the edit the outage interrupted;
// editor.js reads GET v1/models again).
const whenBack = [];
export const serverDown = () => DOWN.includes($('status').textContent);
export const bannerLasts = () => Boolean(ui.errorOwner && ui.errorOwner.lasting);

function back() {
  const wasDown = serverDown();
  if (wasDown) $('status').textContent = 'connected';
  if (ui.currentError && ui.currentError.status === 0 && !bannerLasts()) clearError();
  if (wasDown) whenBack.forEach((fn) => fn());
}

// ``fn`` runs each time the server is found back after the status said it was down.
export function onBack(fn) {
  whenBack.push(fn);
}

// Whether the banner is about the server or the page rather than the pose shown: the server
// down (while the status says so; not a lasting banner, about its edit), an API key needed,
// the models loading (not connected yet), a 3D view that cannot start. Reset and a sample
// chosen leave such a banner up (solve.js replacedError).
export function aboutServer(e) {
  return (e.status === 0 && DOWN.includes($('status').textContent) && !bannerLasts()) || e.status === 401
    || (e.status === 503 && !ui.connected) || e.title === 'WebGL unavailable';
}

// ``signal``: the caller's, to give the request up (an ApiError 'Given up', status -1,
// which says nothing to the user: the caller dropped the answer).
export async function api(method, path, body, { signal = null } = {}) {
  const headers = { Accept: 'application/json, application/problem+json' };
  if (body !== undefined) headers['Content-Type'] = 'application/json';
  const key = apiKey();
  if (key) headers['X-API-Key'] = key;
  const t0 = performance.now();
  const controller = new AbortController();
  let timedOut = false;
  const timer = setTimeout(() => {
    timedOut = true;
    controller.abort();
  }, NO_ANSWER_MS);
  const giveUp = () => controller.abort();
  if (signal) signal.addEventListener('abort', giveUp);
  let res;
  let text;
  try {
    res = await fetch(path, {
      method,
      headers,
      body: body === undefined ? undefined : JSON.stringify(body),
      cache: 'no-store',
      signal: controller.signal,
    });
    text = await res.text();
  } catch (err) {
    if (timedOut) {
      down(NOT_ANSWERING);
      throw new ApiError(0, 'No answer', `${method} /${path}: the server did not answer within `
        + `${NO_ANSWER_MS / 1000} s; given up`);
    }
    if (signal && signal.aborted) throw new ApiError(-1, 'Given up', `${method} /${path}`);
    down('server unreachable');
    throw new ApiError(0, 'Server unreachable', `${method} /${path} failed (${err.message})`);
  } finally {
    clearTimeout(timer);
    if (signal) signal.removeEventListener('abort', giveUp);
  }
  back();
  const rtt = performance.now() - t0;
  let data = null;
  try {
    data = text ? JSON.parse(text) : null;
  } catch {
    data = null;
  }
  const requestId = res.headers.get('X-Request-ID');
  if (res.status === 401) keyNeeded();
  else if (res.ok) $('api-key').removeAttribute('aria-invalid');
  if (!res.ok) {
    const title = (data && data.title) || `HTTP ${res.status}`;
    let detail = (data && data.detail) || text.slice(0, 300) || res.statusText;
    if (res.status === 401) detail += ' (enter the key under Connection, in the panel)';
    const after = Number.parseInt(res.headers.get('Retry-After') || '', 10); // (seconds; a date: none)
    throw new ApiError(res.status, title, detail, requestId, Number.isFinite(after) && after > 0 ? after : null);
  }
  if (data === null) {
    throw new ApiError(res.status, 'Bad response', `${method} /${path}: the body is not JSON`, requestId);
  }
  return { data, rtt, serverTime: res.headers.get('X-Total-Time') || res.headers.get('X-Inference-Time'), requestId };
}

// A 401: the service runs with an API key (POSE_API_KEY) and none, or another, was sent.
// The key's field is in the panel's Connection box, closed by default: opened and marked
// (the banner said only "send the API key in the X-API-Key header", the field out of sight).
function keyNeeded() {
  const input = $('api-key');
  const box = input.closest('details');
  if (box) box.open = true;
  input.setAttribute('aria-invalid', 'true');
}

// ------------------------------------------------------------------------------------
// Error banner
// ------------------------------------------------------------------------------------
// ``owner``: the edit a failed solve's banner belongs to (solve.js: undone, the banner goes;
// ``lasting``, it stays once the server is back, and until an edit's answer is committed:
// ``back``).
export function showError(err, owner = null) {
  const e = err instanceof ApiError ? err : new ApiError(-1, 'Editor error', String(err && err.message || err));
  ui.currentError = {
    status: e.status,
    title: e.title,
    detail: e.detail,
    requestId: e.requestId,
  };
  $('error-title').textContent = e.status > 0 ? `${e.status} ${e.title}` : e.title;
  $('error-detail').textContent = e.detail;
  $('error-meta').textContent = e.requestId ? `request id ${e.requestId}` : '';
  $('error').hidden = false;
  ui.errorOwner = owner;
}

export function clearError() {
  ui.currentError = null;
  ui.errorOwner = null;
  $('error').hidden = true;
}
