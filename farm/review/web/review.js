// The review page: filters, a paged grid of trees, the selected tree in 3D with its images, verdicts by key.
import * as api from './api.js';
import { TreeViewer } from './viewer.js';
import { VRMode } from './vr.js';

const $ = (id) => document.getElementById(id);
const params = new URLSearchParams(location.search);
const state = { summary: null, page: 1, pages: 1, trees: [], selected: -1, view: 0, detail: null, mode: 'desktop' };
window.reviewApp = state;  // for tests and the console

function status(text) { $('status').textContent = text || ''; }
function reviewer() { return $('reviewer').value.trim() || 'reviewer'; }

function filters() {
  return { batch: $('filter-batch').value, species: $('filter-species').value, generator: $('filter-generator').value,
           verdict: $('filter-verdict').value, flag: $('filter-flag').value, reviewer: reviewer(),
           page: state.page, per_page: 24 };
}

function fillSelect(select, values, label = (v) => v) {
  for (const value of values) select.add(new Option(label(value), value));
}

function badges(entry) {
  const out = [];
  if (entry.mine) out.push(`<span class="badge ${entry.mine}">${entry.mine}</span>`);
  for (const flag of Object.keys(entry.flags || {})) out.push(`<span class="badge qa" title="${flag}">QA</span>`);
  return out.join('');
}

async function loadPage(selectIndex = 0, pending = null) {
  const result = await (pending || api.trees(filters()));
  state.trees = result.trees;
  state.pages = result.pages;
  state.page = result.page;
  $('page-info').textContent = `page ${result.page} / ${result.pages} (${result.total} trees)`;
  $('page-prev').disabled = result.page <= 1;
  $('page-next').disabled = result.page >= result.pages;
  const grid = $('grid');
  grid.replaceChildren();
  const cards = state.trees.map((entry, i) => {
    const card = document.createElement('div');
    card.className = 'card';
    card.dataset.treeId = entry.tree_id;
    card.innerHTML = `<img alt=""><div class="id">${entry.index} ${entry.species}</div><div class="badges">${badges(entry)}</div>`;
    card.addEventListener('click', () => select(i));
    grid.appendChild(card);
    return card;
  });
  // The selected tree's requests go out first: thumbnails queue behind them on the browser's few connections.
  const selecting = state.trees.length ? select(Math.min(selectIndex < 0 ? state.trees.length - 1 : selectIndex,
                                                         state.trees.length - 1)) : null;
  const thumb = state.summary.sketch_output || state.summary.outputs[0];
  state.trees.forEach((entry, i) => {
    if (!thumb || entry.n_views === 0) return;
    api.imageURL(entry.tree_id, 0, thumb).then((url) => { cards[i].querySelector('img').src = url; })
      .catch((error) => console.warn(`thumbnail of ${entry.tree_id}: ${error.message}`));
  });
  if (selecting) await selecting;
  else { state.selected = -1; $('tree-title').textContent = 'no trees match'; }
  if (state.mode === 'vr') await vr.layout(state.trees);
}

async function select(i) {
  state.selected = i;
  const entry = state.trees[i];
  document.querySelectorAll('.card').forEach((card, k) => card.classList.toggle('selected', k === i));
  document.querySelectorAll('.card')[i]?.scrollIntoView({ block: 'nearest' });
  $('tree-title').textContent = entry.tree_id;
  status(`loading ${entry.tree_id} ...`);
  const [detail, buffer, skeleton] = await Promise.all([
    api.tree(entry.tree_id, reviewer()),
    entry.error ? null : api.glb(entry.tree_id).catch((error) => { status(error.message); return null; }),
    entry.error ? null : api.skeleton(entry.tree_id)]);
  if (state.trees[state.selected] !== entry) return;  // another tree was selected meanwhile
  state.detail = detail;
  showDetail(detail);
  if (buffer) { await viewer.show(buffer, skeleton); status(''); } else status(entry.error || 'no mesh stored');
}

function showDetail(detail) {
  const triangles = detail.triangles == null ? '-' : detail.triangles.toLocaleString();
  $('tree-facts').textContent = `${detail.species} (${detail.generator || '?'}) · ${detail.batch} · height ` +
    `${detail.height?.toFixed(2) ?? '-'} m · crown ${detail.crown_radius?.toFixed(2) ?? '-'} m · ${triangles} triangles`;
  const views = $('views');
  views.replaceChildren();
  state.view = Math.min(state.view, Math.max(detail.views.length - 1, 0));
  detail.views.forEach(({ view, name }) => {
    const button = document.createElement('button');
    button.textContent = name;
    button.classList.toggle('active', view === state.view);
    button.addEventListener('click', () => { state.view = view; showDetail(detail); });
    views.appendChild(button);
  });
  showImages(detail);
  const flags = state.summary.flags;
  $('qa-flags').innerHTML = Object.entries(detail.flags).map(([flag, value]) =>
    `<li title="${flags[flag] || ''}">${flag}: ${Number(value).toPrecision(3)}</li>`).join('');
  $('reviews').innerHTML = detail.reviews.map((r) =>
    `<li><span class="badge ${r.verdict}">${r.verdict}</span> ${escapeHTML(r.reviewer)}${r.note ? ': ' + escapeHTML(r.note) : ''}</li>`).join('');
  $('params').textContent = JSON.stringify(detail.params, null, 1);
}

function showImages(detail) {
  const outputs = state.summary.outputs;
  const pairs = [['sketch-image', state.summary.sketch_output], ['depth-image', outputs.includes('depth') ? 'depth' : outputs.find((o) => o.includes('depth'))]];
  for (const [id, output] of pairs) {
    const img = $(id);
    img.removeAttribute('src');
    if (output && detail.views.length) api.imageURL(detail.tree_id, state.view, output).then((url) => {
      if (state.detail === detail) img.src = url;
    });
  }
}

function escapeHTML(text) {
  return String(text).replace(/[&<>"']/g, (c) => ({ '&': '&amp;', '<': '&lt;', '>': '&gt;', '"': '&quot;', "'": '&#39;' }[c]));
}

async function move(step) {
  const next = state.selected + step;
  if (next >= 0 && next < state.trees.length) return select(next);
  if (step > 0 && state.page < state.pages) { state.page += 1; return loadPage(0); }
  if (step < 0 && state.page > 1) { state.page -= 1; return loadPage(-1); }
  status(step > 0 ? 'last tree' : 'first tree');
}

async function verdict(kind, treeId = state.trees[state.selected]?.tree_id) {
  if (!treeId) return;
  const note = $('note').value.trim();
  if (kind === 'flag' && !note) { $('note').focus(); status('type what is wrong, then press Enter to flag'); return; }
  try {
    const stored = await api.postVerdict(treeId, reviewer(), kind, note);
    $('note').value = '';
    const entry = state.trees.find((t) => t.tree_id === treeId);
    if (entry) {
      entry.mine = stored.verdict;
      const card = document.querySelector(`.card[data-tree-id="${CSS.escape(treeId)}"] .badges`);
      if (card) card.innerHTML = badges(entry);
    }
    status(`${stored.verdict}: ${treeId}`);
    window.lastVerdict = stored;
    if (state.mode === 'desktop' && $('advance').checked && treeId === state.trees[state.selected]?.tree_id) await move(1);
    else if (state.mode === 'desktop') showDetail(await api.tree(treeId, reviewer()));
  } catch (error) { status(`verdict not stored: ${error.message}`); }
}

const keys = { a: () => verdict('approve'), r: () => verdict('reject'), f: () => verdict('flag'),
               n: () => move(1), ArrowRight: () => move(1), p: () => move(-1), ArrowLeft: () => move(-1) };
document.addEventListener('keydown', (event) => {
  if (event.target === $('note') && event.key === 'Enter') { event.preventDefault(); verdict('flag'); $('note').blur(); return; }
  if (event.target.matches('input, select, textarea') || event.ctrlKey || event.metaKey || event.altKey) return;
  const action = keys[event.key];
  if (action) { event.preventDefault(); action(); }
});

function changeFilters() { state.page = 1; loadPage(0); }

const viewer = new TreeViewer($('viewer'));
window.reviewViewer = viewer;
const vr = new VRMode(viewer, {
  verdict: (kind, treeId) => verdict(kind, treeId),
  page: (step) => { const page = state.page + step; if (page >= 1 && page <= state.pages) { state.page = page; return loadPage(0); } },
  modeChanged: (mode) => { state.mode = mode; },
});
state.vr = vr;

async function start() {
  $('reviewer').value = params.get('reviewer') || localStorage.getItem('treefarm.reviewer') || '';
  $('reviewer').addEventListener('change', () => { localStorage.setItem('treefarm.reviewer', reviewer()); loadPage(state.selected); });
  const firstPage = api.trees(filters());  // in parallel with the summary: the first tree sooner on screen
  state.summary = await api.batches();
  $('dataset').textContent = `${state.summary.dataset} · ${state.summary.trees} trees`;
  fillSelect($('filter-batch'), state.summary.batches.map((b) => b.id));
  fillSelect($('filter-species'), state.summary.species);
  fillSelect($('filter-generator'), state.summary.generators);
  fillSelect($('filter-verdict'), state.summary.verdicts);
  fillSelect($('filter-flag'), Object.keys(state.summary.flags));
  for (const id of ['filter-batch', 'filter-species', 'filter-generator', 'filter-verdict', 'filter-flag'])
    $(id).addEventListener('change', changeFilters);
  $('page-prev').addEventListener('click', () => { state.page -= 1; loadPage(0); });
  $('page-next').addEventListener('click', () => { state.page += 1; loadPage(0); });
  $('approve').addEventListener('click', () => verdict('approve'));
  $('reject').addEventListener('click', () => verdict('reject'));
  $('flag').addEventListener('click', () => verdict('flag'));
  $('show-skeleton').addEventListener('change', (e) => viewer.setSkeletonVisible(e.target.checked));
  const button = $('enter-vr');
  vr.supported().then((supported) => {
    if (!supported) return;
    button.disabled = false;
    button.textContent = 'Enter VR';
    button.title = 'review this page in a VR headset';
    button.addEventListener('click', () => vr.enter(state.trees).catch((error) => status(`VR failed: ${error.message}`)));
  });
  await loadPage(0, firstPage);
}

start().catch((error) => { status(`cannot load: ${error.message}`); console.error(error); });
