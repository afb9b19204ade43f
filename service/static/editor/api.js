// The editor's API helper and error banner: every request to the service goes through api();
// failures (application/problem+json, or no answer at all) become ApiError and are shown.

import { $, ui } from './state.js';

// ------------------------------------------------------------------------------------
// API helper: every call goes through here; failures become ApiError and are shown.
// ------------------------------------------------------------------------------------
export class ApiError extends Error {
  constructor(status, title, detail, requestId = null) {
    super(`${title}: ${detail}`);
    this.status = status;
    this.title = title;
    this.detail = detail;
    this.requestId = requestId;
  }
}

function apiKey() {
  return $('api-key').value.trim();
}

export async function api(method, path, body) {
  const headers = { Accept: 'application/json, application/problem+json' };
  if (body !== undefined) headers['Content-Type'] = 'application/json';
  const key = apiKey();
  if (key) headers['X-API-Key'] = key;
  const t0 = performance.now();
  let res;
  try {
    res = await fetch(path, {
      method,
      headers,
      body: body === undefined ? undefined : JSON.stringify(body),
      cache: 'no-store',
    });
  } catch (err) {
    $('status').textContent = 'server unreachable';
    throw new ApiError(0, 'Server unreachable', `${method} /${path} failed (${err.message})`);
  }
  if ($('status').textContent === 'server unreachable') $('status').textContent = 'connected';
  const text = await res.text();
  const rtt = performance.now() - t0;
  let data = null;
  try {
    data = text ? JSON.parse(text) : null;
  } catch {
    data = null;
  }
  const requestId = res.headers.get('X-Request-ID');
  if (!res.ok) {
    const title = (data && data.title) || `HTTP ${res.status}`;
    const detail = (data && data.detail) || text.slice(0, 300) || res.statusText;
    throw new ApiError(res.status, title, detail, requestId);
  }
  if (data === null) {
    throw new ApiError(res.status, 'Bad response', `${method} /${path}: the body is not JSON`, requestId);
  }
  return { data, rtt, serverTime: res.headers.get('X-Total-Time') || res.headers.get('X-Inference-Time'), requestId };
}

// ------------------------------------------------------------------------------------
// Error banner
// ------------------------------------------------------------------------------------
export function showError(err) {
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
}

export function clearError() {
  ui.currentError = null;
  $('error').hidden = true;
}
