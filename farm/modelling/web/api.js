// The modelling server's JSON API: one POST per tool, every request carrying the access token in a header.
const token = document.querySelector('meta[name="review-token"]').content;

export class ApiError extends Error {
  constructor(message, status) { super(message); this.status = status; }
}

async function request(path, options = {}) {
  const headers = { 'X-Review-Token': token, ...(options.headers || {}) };
  const response = await fetch(path, { ...options, headers });
  if (!response.ok) {
    let message = `${response.status} ${response.statusText}`;
    try { message = (await response.json()).error || message; } catch (_) { /* body was not JSON */ }
    throw new ApiError(message, response.status);
  }
  return response;
}

export async function post(path, body = {}) {
  const options = { method: 'POST', body: typeof body === 'string' ? body : JSON.stringify(body),
                    headers: { 'Content-Type': 'application/json' } };
  return (await request(`/api/${path}`, options)).json();
}

export const state = async () => (await request('/api/version')).json();
export const sessionURL = () => `/api/session?token=${encodeURIComponent(token)}`;

// The GLB of `version`, or null when a newer edit overtook the request (the server drops it).
export async function grow(version) {
  try {
    const response = await request('/api/grow', { method: 'POST', body: JSON.stringify({ version }),
                                                  headers: { 'Content-Type': 'application/json' } });
    return { version: Number(response.headers.get('X-Session-Version')), glb: await response.arrayBuffer() };
  } catch (error) {
    if (error.status === 409) return null;
    throw error;
  }
}
