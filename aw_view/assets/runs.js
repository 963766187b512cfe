// The runs page: one row per episode, polled from /api/runs (a 304 when nothing changed), sorted
// and filtered here. Times are wall-clock seconds from the server; elapsed time, budget left
// and "stuck" are worked out here every second, so they tick between updates.
(function () {
  "use strict";
  const STATUSES = ["queued", "running", "finished", "error", "timed out", "interrupted", "unreadable"];
  const POLL_MS = 500;
  const tbody = document.querySelector("#runs tbody");
  const fSystem = document.getElementById("f-system");
  const fStatus = document.getElementById("f-status");
  const conn = document.getElementById("conn");
  let data = { rows: [], problems: [], stuck_seconds: 120 };
  let etag = null, skew = 0, sortKey = "system", sortDir = 1, polls = 0;
  const rows = new Map(); // id -> tr

  STATUSES.forEach(function (s) { const o = document.createElement("option"); o.value = s; o.textContent = s; fStatus.appendChild(o); });

  function now() { return Date.now() / 1000 + skew; }
  function dur(s) {
    if (s === null || s === undefined || !isFinite(s)) return "";
    const neg = s < 0; s = Math.abs(s);
    const h = Math.floor(s / 3600), m = Math.floor((s % 3600) / 60), sec = Math.floor(s % 60);
    const txt = h ? h + "h " + String(m).padStart(2, "0") + "m" : m ? m + "m " + String(sec).padStart(2, "0") + "s" : sec + "s";
    return (neg ? "-" : "") + txt;
  }
  function elapsed(r) {
    if (r.ended_t !== undefined && r.ended_t !== null) return r.ended_t;
    if (r.status === "running") return r.clock_start ? now() - r.clock_start : null;
    return r.last_t !== undefined ? r.last_t : null; // stopped without an end record: its last call
  }
  function stuck(r) {
    return r.status === "running" && r.last_activity && now() - r.last_activity > data.stuck_seconds;
  }
  function sortValue(r, k) {
    if (k === "status") return STATUSES.indexOf(r.status);
    if (k === "calls") return r.calls || 0;
    if (k === "elapsed") { const e = elapsed(r); return e === null ? -1 : e; }
    if (k === "left") { const e = elapsed(r); return r.budget_s && e !== null ? r.budget_s - e : Infinity; }
    if (k === "last") return r.last ? r.last.tool : "";
    return String(r[k] || "");
  }
  function episodeUrl(id) { return "/episode/" + id.split("/").map(encodeURIComponent).join("/"); }
  function cell(tr, i) { return tr.cells[i]; }
  function setText(el, text) { if (el.textContent !== text) el.textContent = text; }

  function makeRow(r) {
    const tr = document.createElement("tr");
    tr.dataset.id = r.id;
    for (let i = 0; i < 8; i++) tr.appendChild(document.createElement("td"));
    tr.cells[3].className = "r calls"; tr.cells[4].className = "r elapsed"; tr.cells[5].className = "r left";
    tr.cells[2].className = "status"; tr.cells[6].className = "last"; tr.cells[7].className = "thumb";
    const a = document.createElement("a");
    a.href = episodeUrl(r.id);
    tr.cells[1].appendChild(a);
    return tr;
  }
  function fillRow(tr, r) {
    setText(cell(tr, 0), r.system);
    setText(tr.cells[1].firstChild, r.task_id);
    const st = cell(tr, 2);
    const key = r.status + "|" + (r.detail || "") + "|" + stuck(r);
    if (st.dataset.key !== key) {
      st.dataset.key = key;
      st.textContent = "";
      const badge = document.createElement("span");
      badge.className = "st st-" + r.status.replace(" ", "-");
      badge.textContent = r.status;
      st.appendChild(badge);
      if (stuck(r)) {
        const s = document.createElement("span");
        s.className = "stuck-badge";
        s.textContent = "stuck";
        st.appendChild(s);
      }
      if (r.detail) {
        const d = document.createElement("span");
        d.className = "detail";
        d.textContent = r.detail;
        st.appendChild(d);
      }
    }
    tr.classList.toggle("stuck", !!stuck(r));
    tr.dataset.status = r.status;
    setText(cell(tr, 3), String(r.calls || 0));
    const e = elapsed(r);
    let el = dur(e);
    if (e === null && r.status === "running") el = r.clock_start ? "" : "not started";
    setText(cell(tr, 4), el);
    setText(cell(tr, 5), r.budget_s && e !== null ? dur(r.budget_s - e) : "");
    const last = r.last ? r.last.tool + (r.last.ok ? "" : " \u2717 " + r.last.error) : "";
    setText(cell(tr, 6), last);
    cell(tr, 6).classList.toggle("err", !!(r.last && !r.last.ok));
    const th = cell(tr, 7);
    const src = r.thumb ? "/capture?id=" + encodeURIComponent(r.id) + "&name=" + encodeURIComponent(r.thumb) + "&thumb=1" : "";
    if ((th.dataset.src || "") !== src) {
      th.dataset.src = src;
      th.textContent = "";
      if (src) {
        const img = document.createElement("img");
        img.src = src; img.alt = "latest capture of " + r.task_id; img.loading = "lazy";
        th.appendChild(img);
      }
    }
  }
  function options(select, values) {
    const have = Array.from(select.options).map(function (o) { return o.value; }).slice(1);
    values.filter(function (v) { return have.indexOf(v) < 0; }).forEach(function (v) {
      const o = document.createElement("option"); o.value = v; o.textContent = v; select.appendChild(o);
    });
  }
  function render() {
    const systems = Array.from(new Set(data.rows.map(function (r) { return r.system; }))).sort();
    options(fSystem, systems);
    const seen = new Set();
    const shown = data.rows.filter(function (r) {
      return (!fSystem.value || r.system === fSystem.value) && (!fStatus.value || r.status === fStatus.value);
    });
    shown.sort(function (a, b) {
      const x = sortValue(a, sortKey), y = sortValue(b, sortKey);
      if (x < y) return -sortDir;
      if (x > y) return sortDir;
      return a.id < b.id ? -1 : a.id > b.id ? 1 : 0;
    });
    shown.forEach(function (r, i) {
      let tr = rows.get(r.id);
      if (!tr) { tr = makeRow(r); rows.set(r.id, tr); }
      fillRow(tr, r);
      if (tbody.children[i] !== tr) tbody.insertBefore(tr, tbody.children[i] || null);
      seen.add(r.id);
    });
    rows.forEach(function (tr, id) {
      if (!seen.has(id)) { tr.remove(); if (!data.rows.some(function (r) { return r.id === id; })) rows.delete(id); }
    });
    const counts = {};
    data.rows.forEach(function (r) { counts[r.status] = (counts[r.status] || 0) + 1; });
    setText(document.getElementById("counts"), STATUSES.filter(function (s) { return counts[s]; })
      .map(function (s) { return counts[s] + " " + s; }).join(" \u00b7 "));
    const probs = document.getElementById("problems");
    const ptext = data.problems.join("\n");
    if (probs.dataset.text !== ptext) {
      probs.dataset.text = ptext;
      probs.textContent = "";
      data.problems.forEach(function (p) { const d = document.createElement("div"); d.textContent = p; probs.appendChild(d); });
    }
  }
  function poll() {
    const headers = etag ? { "If-None-Match": etag } : {};
    fetch("/api/runs", { headers: headers, cache: "no-store" })
      .then(function (r) {
        if (r.status === 304) return null;
        if (!r.ok) throw new Error("HTTP " + r.status);
        const date = r.headers.get("Date");
        if (date) skew = Date.parse(date) / 1000 - Date.now() / 1000;
        etag = r.headers.get("ETag");
        return r.json();
      })
      .then(function (d) {
        polls += 1;
        document.body.dataset.polls = String(polls);
        conn.textContent = "live"; conn.className = "note";
        if (d) {
          data = d;
          document.getElementById("root").textContent = d.root;
        }
        render();
      })
      .catch(function (err) {
        conn.textContent = "the viewer is not answering (" + err.message + ")"; conn.className = "down";
      })
      .then(function () { setTimeout(poll, POLL_MS); });
  }
  document.querySelectorAll("#runs th[data-k]").forEach(function (th) {
    th.addEventListener("click", function () {
      const k = th.dataset.k;
      sortDir = sortKey === k ? -sortDir : 1;
      sortKey = k;
      document.querySelectorAll("#runs th").forEach(function (h) { h.removeAttribute("aria-sort"); });
      th.setAttribute("aria-sort", sortDir > 0 ? "ascending" : "descending");
      render();
    });
  });
  fSystem.addEventListener("change", render);
  fStatus.addEventListener("change", render);
  setInterval(render, 1000); // elapsed time and "stuck" tick between updates
  poll();
})();
