// trackingbox live view: one server-sent event stream (/events) whose first message is a snapshot of
// the run and whose next ones are updates; uPlot (vendored, /static) draws the charts.
"use strict";

const MAX_POINTS = 8000;   // the server's rule: row i kept while i % stride == 0, stride doubles past this
const COLORS = { parameter: "#1f5fbf", truth: "#111111", band: "rgba(31,95,191,0.15)", measured: "#d1495b",
                 tracked: "#1f5fbf", untracked: "#9aa0a6", hold: "rgba(255,170,0,0.16)" };

const S = { meta: null, rows: [], stride: 1, n: 0, last: null, loops: {}, holds: {}, tags: [], health: null,
            healthAt: 0, seen: 0, charts: [], drawPending: false };

const $ = (sel) => document.querySelector(sel);
const el = (tag, attrs = {}, text = "") => {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
  if (text !== "") e.textContent = text;
  return e;
};

function num(text) {                      // a CSV cell as a number (empty: NaN)
  if (text === undefined || text === null || text === "") return NaN;
  return Number(text);
}
function fmt(x) {
  if (x === null || x === undefined || !Number.isFinite(x)) return "–";
  if (x === 0) return "0";
  const a = Math.abs(x);
  return (a >= 1e6 || a < 1e-3) ? x.toExponential(5) : String(Number(x.toPrecision(6)));
}
function fmtAxis(x) {                    // short tick labels
  if (x === null || !Number.isFinite(x)) return "";
  if (x === 0) return "0";
  const a = Math.abs(x);
  return (a >= 1e5 || a < 1e-2) ? x.toExponential(2) : String(Number(x.toPrecision(4)));
}
function ago(s) {
  if (s === null || s === undefined || !Number.isFinite(s)) return "–";
  if (s < 60) return `${s.toFixed(1)} s ago`;
  if (s < 3600) return `${(s / 60).toFixed(1)} min ago`;
  return `${(s / 3600).toFixed(1)} h ago`;
}
function span(s) {
  if (s === null || s === undefined || !Number.isFinite(s)) return "–";
  if (Math.abs(s) < 120) return `${fmt(s)} s`;
  if (Math.abs(s) < 7200) return `${fmt(s / 60)} min`;
  return `${fmt(s / 3600)} h`;
}
function plantTime(t) {                   // t: s from the run's first sample
  if (t === null || t === undefined || !Number.isFinite(t)) return "–";
  if (S.meta && S.meta.origin !== null) {
    return new Date((S.meta.origin + t) * 1000).toISOString().replace("T", " ").replace(/\.\d+Z$/, " UTC");
  }
  return `t = ${span(t)}`;
}
function wallTime(epoch) {
  if (!epoch) return "";
  return new Date(epoch * 1000).toISOString().substring(11, 19);
}
function xOf(t) { return S.meta && S.meta.origin !== null ? S.meta.origin + t : t / 3600; }

// ------------------------------------------------------------------ charts

function holdShading(tag) {
  return (u) => {
    const holds = S.holds[tag] || [];
    if (!holds.length) return;
    const ctx = u.ctx, top = u.bbox.top, height = u.bbox.height;
    const end = S.last ? num(S.last.time) : NaN;
    ctx.save();
    ctx.fillStyle = COLORS.hold;
    for (const [a, b] of holds) {
      const x0 = u.valToPos(xOf(a), "x", true);
      const x1 = u.valToPos(xOf(b === null ? end : b), "x", true);
      if (Number.isFinite(x0) && Number.isFinite(x1)) ctx.fillRect(x0, top, Math.max(1, x1 - x0), height);
    }
    ctx.restore();
  };
}

function makeChart(box, title, series, tag, bands, note) {
  const h = el("h3", {}, title);
  box.appendChild(h);
  if (note) box.appendChild(el("div", { class: "legend-note" }, note));
  const target = el("div");
  box.appendChild(target);
  const width = Math.max(320, Math.floor(box.getBoundingClientRect().width || 560) - 4);
  const opts = {
    width, height: 200,
    scales: { x: { time: S.meta.origin !== null } },
    axes: [{ label: S.meta.origin !== null ? "" : "h" }, { size: 72, values: (u, splits) => splits.map(fmtAxis) }],
    series: [{}].concat(series.map((s) => ({ label: s.label, stroke: s.color, width: s.width || 1.5,
                                           dash: s.dash, fill: s.fill, points: { show: false },
                                           spanGaps: false }))),
    bands: bands || [],
    hooks: { drawClear: [holdShading(tag)] },
    legend: { live: false },
  };
  const chart = new uPlot(opts, [[]].concat(series.map(() => [])), target);
  return { chart, columns: series.map((s) => s.column) };
}

function buildCharts() {
  const root = $("#charts");
  root.innerHTML = "";
  S.charts = [];
  if (!S.meta) return;
  for (const p of S.meta.pairs) {
    const pbox = el("div", { class: "chart", "data-parameter": p.parameter });
    root.appendChild(pbox);
    const series = [{ label: p.parameter, column: `parameter:${p.parameter}`, color: COLORS.parameter, width: 2 }];
    const bands = [];
    if (p.band) {
      series.push({ label: "band (upper)", column: p.band[1], color: "rgba(31,95,191,0.35)", width: 1 });
      series.push({ label: "band (lower)", column: p.band[0], color: "rgba(31,95,191,0.35)", width: 1 });
      bands.push({ series: [2, 3], fill: COLORS.band });
    }
    if (p.truth) series.push({ label: "plant's truth", column: p.truth, color: COLORS.truth, dash: [6, 4] });
    const bounds = (p.lower !== null && p.upper !== null) ? `bounds ${fmt(p.lower)} … ${fmt(p.upper)}` : "";
    S.charts.push(makeChart(pbox, `parameter ${p.parameter} (paired with ${p.tag})`, series, p.tag, bands,
                            [bounds, p.band ? `band: ${p.band.join(" / ")}` : "", p.truth ? "truth: truth.json" : "",
                             "shaded: loop held"].filter(Boolean).join(" · ")));
    const tbox = el("div", { class: "chart", "data-tag": p.tag });
    root.appendChild(tbox);
    // the measurement drawn last, on top of the tracked line it should sit on
    S.charts.push(makeChart(tbox, `${p.tag}: measured / tracked / untracked`, [
      { label: "untracked", column: `untracked:${p.tag}`, color: COLORS.untracked, width: 1.5, dash: [4, 3] },
      { label: "tracked", column: `tracked:${p.tag}`, color: COLORS.tracked, width: 2.5 },
      { label: "measured", column: `measured:${p.tag}`, color: COLORS.measured, width: 1 },
    ], p.tag, [], ""));
  }
}

function drawCharts() {
  S.drawPending = false;
  if (!S.meta) return;
  const index = {};
  S.meta.series.forEach((c, j) => { index[c] = j + 1; });
  const rows = S.rows.slice();
  // the last row, where it is not a kept one, ends the lines where the run is
  if (S.last && S.n > 0 && (!rows.length || rows[rows.length - 1][0] !== S.n - 1)) {
    const r = [S.n - 1];
    for (const c of S.meta.series) {
      r.push(c.startsWith("truth:") ? (rows.length ? rows[rows.length - 1][index[c]] : null) : num(S.last[c]));
    }
    rows.push(r);
  }
  const xs = rows.map((r) => xOf(r[index.time]));
  for (const { chart, columns } of S.charts) {
    const data = [xs];
    for (const c of columns) {
      const j = index[c];
      data.push(rows.map((r) => { const v = r[j]; return (v === null || !Number.isFinite(v)) ? null : v; }));
    }
    chart.setData(data);
  }
}
function scheduleDraw() {
  if (!S.drawPending) { S.drawPending = true; setTimeout(() => requestAnimationFrame(drawCharts), 200); }
}

// ------------------------------------------------------------------ tables

function renderLoops() {
  const body = $("#loops tbody");
  body.innerHTML = "";
  if (!S.meta) return;
  for (const p of S.meta.pairs) {
    const st = S.loops[p.tag] || { state: "–", why: "", since: null };
    const tr = el("tr", { "data-tag": p.tag, "data-state": st.state, "data-why": st.why });
    const v = (c) => (S.last ? num(S.last[c]) : NaN);
    tr.appendChild(el("td", {}, p.tag));
    tr.appendChild(el("td", {}, p.parameter));
    tr.appendChild(el("td", { class: `state ${st.state}` }, st.state));
    tr.appendChild(el("td", {}, st.why || ""));
    tr.appendChild(el("td", {}, plantTime(st.since)));
    tr.appendChild(el("td", { class: "num" }, fmt(v(`parameter:${p.parameter}`))));
    tr.appendChild(el("td", { class: "num" }, fmt(v(`measured:${p.tag}`))));
    tr.appendChild(el("td", { class: "num" }, fmt(v(`tracked:${p.tag}`))));
    tr.appendChild(el("td", { class: "num" }, fmt(v(`untracked:${p.tag}`))));
    body.appendChild(tr);
  }
}

function renderTags() {
  const body = $("#tags tbody");
  body.innerHTML = "";
  for (const t of S.tags) {
    const live = S.health && S.health.live;
    const tr = el("tr", { "data-tag": t.tag, "data-stale": String(t.stale), class: t.stale ? "stale" : "" });
    tr.appendChild(el("td", {}, t.tag));
    tr.appendChild(el("td", {}, live ? (t.last ? new Date(t.last * 1000).toISOString().replace("T", " ")
                                                   .replace(/\.\d+Z$/, " UTC").replace(/\+.*$/, "") : "–")
                                     : plantTime(t.last)));
    tr.appendChild(el("td", { class: "num" }, span(t.behind)));
    tr.appendChild(el("td", {}, t.quality || "–"));
    tr.appendChild(el("td", {}, t.stale === null ? "–" : (t.stale ? "STALE" : "no")));
    body.appendChild(tr);
  }
}

function renderLastRow() {
  const table = $("#last-row");
  const head = table.querySelector("thead tr"), row = table.querySelector("tbody tr");
  head.innerHTML = ""; row.innerHTML = "";
  if (!S.last || !S.meta) { table.dataset.time = ""; return; }
  table.dataset.time = S.last.time;
  for (const c of S.meta.columns) {
    head.appendChild(el("th", {}, c));
    const raw = S.last[c];
    const shown = c.startsWith("mode:") ? raw : (c === "time" ? plantTime(num(raw)) : fmt(num(raw)));
    row.appendChild(el("td", { "data-col": c, "data-raw": raw, class: c.startsWith("mode:") ? "" : "num" }, shown));
  }
}

function addEvents(events) {
  const log = $("#log");
  for (const e of events) {
    if (e.seq <= S.seen) continue;
    S.seen = e.seq;
    const li = el("li", { "data-kind": e.kind.split(":")[0], "data-seq": String(e.seq),
                          "data-plant": e.plant === null ? "" : String(e.plant) });
    li.appendChild(el("span", { class: "when" }, `${wallTime(e.wall)}${e.plant !== null ? " · " + plantTime(e.plant) : ""}`));
    li.appendChild(document.createTextNode(e.text));
    log.insertBefore(li, log.firstChild);
  }
  while (log.children.length > 400) log.removeChild(log.lastChild);
}

function renderHealth() {
  const h = S.health;
  if (!h) return;
  const now = Date.now() / 1000, drift = now - S.healthAt;
  $("#rows").textContent = String(S.n);
  document.body.dataset.rows = String(S.n);
  $("#plant-time").textContent = plantTime(S.last ? num(S.last.time) : NaN);
  const link = $("#link");
  let text = "offline run", cls = "";
  if (h.live) {
    if (h.link === "connected") { text = "connected"; cls = "ok"; }
    else if (h.link === "disconnected") { text = `disconnected ${ago(now - h.link_since)}: reconnecting`; cls = "bad"; }
    else if (h.link === "connecting") { text = "connecting"; cls = "warn"; }
    else if (h.link === "stopped") { text = "tracker stopped"; cls = "warn"; }
    if (h.tracker === false && h.link !== "stopped") { text = "tracker not running"; cls = "bad"; }
    else if (h.status_age !== null && h.status_age + drift > 10 && h.link !== "stopped") {
      text = `no word from the tracker for ${span(h.status_age + drift)}`; cls = "bad";
    }
  }
  link.textContent = text; link.className = `pill ${cls}`; link.dataset.link = h.live ? (h.link || "") : "offline";
  $("#last-sample").textContent = h.last_sample_age === null ? "–" : ago(h.last_sample_age + drift);
  $("#reconnects").textContent = h.live ? String(h.reconnects) : "–";
  $("#backfilled").textContent = h.live ? String(h.backfilled) : "–";
  $("#samples").textContent = h.live ? String(h.samples) : "–";
}

// ------------------------------------------------------------------ messages

function takeRows(rows, stride, n) {
  if (stride !== S.stride) {
    S.stride = stride;
    S.rows = S.rows.filter((r) => r[0] % stride === 0);
  }
  const lastIndex = S.rows.length ? S.rows[S.rows.length - 1][0] : -1;
  for (const r of rows) if (r[0] > lastIndex && r[0] % S.stride === 0) S.rows.push(r);
  S.n = n;
}

function onSnapshot(doc) {
  S.meta = doc.meta; S.rows = []; S.stride = doc.stride; S.seen = 0;
  $("#log").innerHTML = "";
  $("#run").textContent = doc.meta.spec ? `${doc.meta.spec} → ${doc.meta.out}` : doc.meta.out;
  takeRows(doc.rows, doc.stride, doc.n);
  onState(doc);
  buildCharts();
  drawCharts();
}
function onUpdate(doc) {
  if (!S.meta) return;
  takeRows(doc.rows, doc.stride, doc.n);
  onState(doc);
  scheduleDraw();
}
function onState(doc) {
  S.last = doc.last; S.loops = doc.loops; S.holds = doc.holds; S.tags = doc.tags;
  S.health = doc.health; S.healthAt = Date.now() / 1000;
  renderLoops(); renderTags(); renderLastRow(); addEvents(doc.events); renderHealth();
  document.body.dataset.updated = String(Date.now());
}

function connect() {
  const stream = $("#stream");
  const source = new EventSource("/events");
  source.addEventListener("snapshot", (m) => onSnapshot(JSON.parse(m.data)));
  source.addEventListener("update", (m) => onUpdate(JSON.parse(m.data)));
  source.onopen = () => { stream.textContent = "page: live"; stream.className = "pill ok"; stream.dataset.stream = "open"; };
  source.onerror = () => { stream.textContent = "page: reconnecting to the view"; stream.className = "pill warn";
                           stream.dataset.stream = "error"; };
}

setInterval(renderHealth, 1000);
connect();
