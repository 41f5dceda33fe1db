// The review server's HTTP API: every request carries the access token in the X-Review-Token header.
// `request` is the modelling page's too (farm/modelling/web/api.js).
export const token = document.querySelector('meta[name="review-token"]').content;

// A fetch with the token; a failed one throws an Error with the server's message and the HTTP `status`.
export async function request(path, options = {}) {
  const headers = { 'X-Review-Token': token, ...(options.headers || {}) };
  const response = await fetch(path, { ...options, headers });
  if (!response.ok) {
    let message = `${response.status} ${response.statusText}`;
    try { message = (await response.json()).error || message; } catch (_) { /* body was not JSON */ }
    throw Object.assign(new Error(message), { status: response.status });
  }
  return response;
}

export async function getJSON(path, params = {}) {
  const query = new URLSearchParams(Object.entries(params).filter(([, v]) => v !== '' && v != null));
  const suffix = query.toString() ? `?${query}` : '';
  return (await request(path + suffix)).json();
}

export const batches = () => getJSON('/api/batches');
export const trees = (filters) => getJSON('/api/trees', filters);
export const tree = (id, reviewer) => getJSON(`/api/trees/${encodeURIComponent(id)}`, { reviewer });
export const skeleton = (id) => getJSON(`/api/trees/${encodeURIComponent(id)}/skeleton`);
export async function glb(id) {
  return (await request(`/api/trees/${encodeURIComponent(id)}/glb`)).arrayBuffer();
}

// Object URLs of view images, kept per (tree, view, output) so paging back costs nothing.
const imageCache = new Map();
export async function imageURL(id, view, output) {
  const key = `${id}/${view}/${output}`;
  if (!imageCache.has(key)) {
    const blob = await (await request(`/api/trees/${encodeURIComponent(id)}/views/${view}/${output}.png`)).blob();
    imageCache.set(key, URL.createObjectURL(blob));
  }
  return imageCache.get(key);
}

export async function postVerdict(treeId, reviewer, verdict, note) {
  const body = JSON.stringify({ tree_id: treeId, reviewer, verdict, note });
  return (await request('/api/verdicts', { method: 'POST', body, headers: { 'Content-Type': 'application/json' } })).json();
}
