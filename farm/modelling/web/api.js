// The modelling server's JSON API: one POST per tool, every request carrying the access token in a header (the
// review client's `request`).
import { request, token } from '../review/api.js';

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
