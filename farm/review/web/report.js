// The evaluation report page: every row of metrics.parquet, worst first; the selected row's panel beside its metrics.
import { getJSON } from './api.js';

const $ = (id) => document.getElementById(id);
const token = document.querySelector('meta[name="review-token"]').content;
const state = { summary: null, rows: [], selected: -1, labels: {} };
window.reportApp = state;  // for tests and the console

function status(text) { $('report-status').textContent = text || ''; }

function escapeHTML(text) {
  return String(text).replace(/[&<>"']/g, (c) => ({ '&': '&amp;', '<': '&lt;', '>': '&gt;', '"': '&quot;', "'": '&#39;' }[c]));
}

function number(value) {
  if (value == null) return '–';
  return Number.isInteger(value) ? String(value) : Number(value).toPrecision(3);
}

function direction(column) {
  if (column.higher_is_better == null) return '';
  return column.higher_is_better ? ' ↑' : ' ↓';
}

function lastLine(text) {
  const lines = String(text || '').trim().split('\n');
  return lines[lines.length - 1];
}

function renderTable() {
  const { columns } = state.summary;
  const heads = ['#', 'method', 'species', 'tree', 'status', 'rank metric', 'value', 'worst'];
  $('report-table').tHead.innerHTML = '<tr>' + heads.map((h) => `<th class="id">${h}</th>`).join('') +
    columns.map((c) => `<th title="${escapeHTML(c.name)}${c.paper ? ' · paper: ' + escapeHTML(c.paper) : ''}">` +
                       `${escapeHTML(c.label)}${direction(c)}</th>`).join('') + '</tr>';
  const body = $('report-table').tBodies[0];
  body.replaceChildren();
  state.rows.forEach((row, k) => {
    const tr = document.createElement('tr');
    tr.className = row.status;
    tr.dataset.index = row.index;
    const source = row.source === 'held-out' ? '' : ` (${escapeHTML(row.source)})`;
    tr.innerHTML = `<td class="num">${row.index}</td><td>${escapeHTML(row.method)}${source}</td>` +
      `<td>${escapeHTML(row.species ?? '')}</td><td>${escapeHTML(row.tree_id)}</td>` +
      `<td class="status" title="${escapeHTML(lastLine(row.error))}">${escapeHTML(row.status)}</td>` +
      `<td>${escapeHTML(state.labels[row.rank_metric] ?? row.rank_metric ?? '–')}</td>` +
      `<td class="num">${number(row.rank_value)}</td>` +
      `<td class="num">${row.rank == null ? '–' : `${row.rank}/${row.rank_of}`}</td>` +
      columns.map((c) => `<td class="num">${number(row.metrics[c.name])}</td>`).join('');
    tr.addEventListener('click', () => select(k));
    body.appendChild(tr);
  });
}

function select(k) {
  if (k < 0 || k >= state.rows.length) return;
  state.selected = k;
  const row = state.rows[k];
  document.querySelectorAll('#report-table tbody tr').forEach((tr, i) => tr.classList.toggle('selected', i === k));
  const pane = $('report-table-pane'), left = pane.scrollLeft;  // scroll to the row, not sideways
  document.querySelectorAll('#report-table tbody tr')[k]?.scrollIntoView({ block: 'nearest' });
  pane.scrollLeft = left;
  $('report-row-title').textContent =
    `${row.method} · ${row.tree_id} · ${row.species ?? '?'} (${row.source}, ${row.status})`;
  const img = $('report-panel');
  img.removeAttribute('src');
  status(row.panel ? `loading the panel of row ${row.index} ...` : 'no panel: the method gave no reconstruction');
  if (row.panel) img.src = `/api/report/rows/${row.index}/panel?token=${encodeURIComponent(token)}`;
  const line = (label, value, attributes = '') => `<tr ${attributes}><td>${label}</td><td class="num">${value}</td></tr>`;
  const lines = state.summary.columns.filter((c) => row.metrics[c.name] != null).map((c) =>
    line(escapeHTML(c.label) + direction(c), number(row.metrics[c.name]),
         `class="${c.name === row.rank_metric ? 'rank' : ''}" title="${escapeHTML(c.name)}"`));
  if (row.rank != null) lines.unshift(line('worst-first rank', `${row.rank} of ${row.rank_of}`, 'class="rank"'));
  const seconds = row.seconds.unit ?? row.seconds.total;
  if (seconds != null) lines.push(line('seconds (unit)', number(seconds)));
  $('report-row-metrics').innerHTML = lines.join('');
  $('report-row-error').textContent = row.error || '';
}

async function loadRows() {
  const method = $('report-method').value;
  state.rows = (await getJSON('/api/report/rows', { method })).rows;
  renderTable();
  if (state.rows.length) select(0);
  else { state.selected = -1; $('report-row-title').textContent = 'no rows'; }
}

const keys = { n: 1, ArrowDown: 1, ArrowRight: 1, p: -1, ArrowUp: -1, ArrowLeft: -1 };
document.addEventListener('keydown', (event) => {
  if (event.target.matches('input, select, textarea') || event.ctrlKey || event.metaKey || event.altKey) return;
  if (event.key in keys) { event.preventDefault(); select(state.selected + keys[event.key]); }
});

async function start() {
  const img = $('report-panel');
  img.addEventListener('load', () => { status(''); window.lastPanelShown = state.rows[state.selected]?.index; });
  img.addEventListener('error', () => { if (img.getAttribute('src')) status('the panel could not be loaded'); });
  state.summary = await getJSON('/api/report');
  state.labels = Object.fromEntries(state.summary.columns.map((c) => [c.name, c.label]));
  const { counts } = state.summary;
  document.title = `treefarm report ${state.summary.report}`;
  $('report-title').textContent = `${state.summary.report} · evaluation report`;
  $('report-counts').textContent = `${state.summary.rows} rows: ${counts.ok} ok, ${counts.failed} failed, ` +
    `${counts.error} errors · worst first`;
  for (const method of state.summary.methods) $('report-method').add(new Option(method, method));
  $('report-method').addEventListener('change', () => loadRows().catch((error) => status(error.message)));
  await loadRows();
}

start().catch((error) => { status(`cannot load: ${error.message}`); console.error(error); });
