// The episode page: the 3D scene at any recorded state (the report's viewer, parts coloured as in
// the captures), following the live episode until the slider is moved; the call list; the
// captures beside the task's reference images; with --suite, the target as a ghost and each
// state's scores. Polls /api/episode for the calls after those it has (a 304 when none).
(function () {
  "use strict";
  const POLL_MS = 500;
  const id = decodeURIComponent(location.pathname.slice("/episode/".length));
  const q = "id=" + encodeURIComponent(id);
  const $ = function (s) { return document.getElementById(s); };
  const plot = $("plot"), slider = $("slider"), follow = $("follow"), label = $("label");
  let calls = [], states = [], generation = null, etag = null, parts = null, plotting = null;
  let shown = -1, scoreMode = null, scores = null, scoreTimer = null, refsShown = false, gone = false;
  document.title = "aw-view: " + id;
  $("title").textContent = id;

  function fmtT(c) { return c.t === null || c.t === undefined ? "" : c.t.toFixed(1); }
  function reset() {
    calls = []; states = []; etag = null; shown = -1; scores = null;
    document.querySelector("#calls tbody").textContent = "";
    $("captures").textContent = "";
    slider.max = "0"; slider.value = "0";
  }
  function stateLabel(k) {
    const st = states[k];
    if (!st) return "";
    const where = st.call === null ? "initial state" : "after call " + st.seq + " (" + st.tool + (st.t !== null ? ", " + st.t.toFixed(1) + " s" : "") + ")";
    return (k + 1) + "/" + states.length + ": " + where;
  }

  // ------------------------------------------------------------------ the scene
  function buildPlot() {
    const stateTraces = parts.map(function (p, i) { return window.AWViewer.mesh(p, states[0].poses, i, 1.0, p.id); });
    const ghostTraces = parts.map(function (p, i) {
      const t = window.AWViewer.mesh(p, states[0].poses, i, 0.25, "target " + p.id);
      t.visible = false;
      return t;
    });
    const layout = { margin: { l: 0, r: 0, t: 0, b: 0 }, showlegend: false, uirevision: "keep",
                     scene: { aspectmode: "data", xaxis: { title: "x" }, yaxis: { title: "y" }, zaxis: { title: "z" } } };
    plotting = window.Plotly.newPlot(plot, stateTraces.concat(ghostTraces), layout, { displaylogo: false, responsive: true })
      .then(function () { plot.dataset.ready = "1"; });
    return plotting;
  }
  function coords(posesOf) {
    const X = [], Y = [], Z = [];
    parts.forEach(function (p, i) {
      const xyz = window.AWViewer.place(p.v, posesOf(p, i));
      X.push(xyz[0]); Y.push(xyz[1]); Z.push(xyz[2]);
    });
    return { x: X, y: Y, z: Z };
  }
  function show(k) {
    if (!parts || !states.length) return;
    k = Math.max(0, Math.min(k, states.length - 1));
    shown = k;
    slider.value = String(k);
    label.textContent = stateLabel(k);
    document.querySelectorAll("#calls tr.shown").forEach(function (tr) { tr.classList.remove("shown"); });
    const row = states[k].call !== null ? document.querySelector('#calls tr[data-i="' + states[k].call + '"]') : null;
    if (row) row.classList.add("shown");
    const poses = states[k].poses;
    const idx = parts.map(function (_, i) { return i; });
    plotting = plotting.then(function () {
      return window.Plotly.restyle(plot, coords(function (p, i) { return poses[i]; }), idx);
    }).then(function () { plot.dataset.state = String(k); plot.dataset.states = String(states.length); });
    showScore();
    askScores();
  }
  function loadScene() {
    fetch("/api/scene?" + q, { cache: "no-store" })
      .then(function (r) { return r.json(); })
      .then(function (d) {
        if (!d.parts) { $("scene-note").textContent = d.problem || d.error || "no scene"; setTimeout(loadScene, 2000); return; }
        $("scene-note").textContent = "";
        parts = d.parts;
        if (states.length) buildPlot().then(function () { show(follow.checked ? states.length - 1 : shown); });
      })
      .catch(function () { setTimeout(loadScene, 2000); });
  }

  // ------------------------------------------------------------------ scores (--suite)
  function fmtScore(s) {
    if (!s) return "";
    if (s.error) return s.error;
    return "PA " + (100 * s.pa).toFixed(1) + "% \u00b7 SR " + (s.sr ? 1 : 0) + " \u00b7 SCD " +
      (s.scd === null ? "\u2013" : (1000 * s.scd).toFixed(2)) + " (" + s.mode + ")";
  }
  function showScore() {
    if (!scores || shown < 0) return;
    let s = scores.states[shown];
    let text = s ? fmtScore(s) : "scoring\u2026";
    if (scores.final && shown === states.length - 1 && calls.length && isEnded()) text = "final: " + fmtScore(scores.final);
    if (scores.error) text = scores.error;
    $("score").textContent = text;
    const ghost = scores.want === shown ? scores.ghost : null;
    const on = !!ghost && $("ghost").checked;
    if (!parts || !plotting) return;
    const P = parts.length, gidx = parts.map(function (_, i) { return P + i; });
    const byId = {};
    (scores.part_ids || []).forEach(function (pid, j) { byId[pid] = j; });
    plotting = plotting.then(function () {
      if (!on) return window.Plotly.restyle(plot, { visible: false }, gidx);
      const c = coords(function (p, i) { return byId[p.id] !== undefined ? ghost[byId[p.id]] : states[shown].poses[i]; });
      c.visible = parts.map(function (p) { return byId[p.id] !== undefined; });
      return window.Plotly.restyle(plot, c, gidx);
    }).then(function () { plot.dataset.ghost = on ? String(shown) : ""; });
  }
  let ended = false;
  function isEnded() { return ended; }
  function askScores() {
    if (scoreMode === false || shown < 0) return;
    clearTimeout(scoreTimer);
    scoreTimer = setTimeout(function () {
      const want = shown;
      fetch("/api/score?" + q + "&want=" + want, { cache: "no-store" })
        .then(function (r) { return r.json(); })
        .then(function (d) {
          if (d.enabled === false) { scoreMode = false; return; }
          scoreMode = true;
          $("ghost-box").hidden = false;
          d.want = want;
          scores = d;
          showScore();
          if (d.pending || (d.note && !d.error)) scoreTimer = setTimeout(askScores, 1000);
        })
        .catch(function () { scoreTimer = setTimeout(askScores, 2000); });
    }, 150);
  }

  // ------------------------------------------------------------------ calls, captures, task
  function captureUrl(name, thumb) {
    return "/capture?" + q + "&name=" + encodeURIComponent(name) + (thumb ? "&thumb=1" : "");
  }
  function figure(href, src, caption) {
    const f = document.createElement("figure"), a = document.createElement("a"), img = document.createElement("img");
    a.href = href; a.target = "_blank"; img.src = src; img.alt = caption; img.loading = "lazy";
    a.appendChild(img);
    const c = document.createElement("figcaption"); c.textContent = caption;
    f.append(a, c);
    return f;
  }
  function addCall(c, i) {
    const tr = document.createElement("tr");
    tr.dataset.i = String(i);
    const cells = [String(c.seq), c.t === null || c.t === undefined ? "before start" : fmtT(c), c.tool];
    cells.forEach(function (t, j) { const td = document.createElement("td"); td.textContent = t; if (j < 2) td.className = "r"; tr.appendChild(td); });
    const args = document.createElement("td"); args.className = "args";
    const code = document.createElement("code"); code.textContent = c.args; args.appendChild(code);
    const res = document.createElement("td");
    if (c.ok) {
      res.className = "ok";
      res.textContent = "ok" + (c.changed ? ": moved " + c.changed.join(", ") : "") + (c.image ? " \u00b7 capture" : "");
    } else {
      res.className = "err";
      res.textContent = "error: " + (c.error || "");
    }
    tr.append(args, res);
    if (c.poses) {
      tr.classList.add("state");
      const k = states.length - 1;
      tr.addEventListener("click", function () { follow.checked = false; show(k); });
    }
    document.querySelector("#calls tbody").appendChild(tr);
    if (c.image) {
      $("captures").appendChild(figure(captureUrl(c.image, false), captureUrl(c.image, true), "call " + c.seq + (c.t !== null && c.t !== undefined ? " \u00b7 " + fmtT(c) + " s" : "")));
      $("n-captures").textContent = String($("captures").children.length);
    }
  }
  function showTask(d) {
    if (refsShown) return;
    if (d.no_task) { $("task").textContent = d.no_task; return; }
    if (!d.task) return;
    refsShown = true;
    $("task").textContent = "condition: " + d.task.condition + (d.task.references ? " \u00b7 reference images:" : " (no reference images)");
    const pre = document.createElement("div"); pre.className = "prompt"; pre.textContent = d.task.prompt;
    $("task").appendChild(pre);
    for (let k = 0; k < d.task.references; k++) {
      const url = "/reference?" + q + "&k=" + k;
      $("references").appendChild(figure(url, url + "&thumb=1", "reference " + (k + 1)));
    }
  }
  function showStatus(row, d) {
    const st = $("status");
    st.textContent = row.status + (row.detail ? ": " + row.detail : "");
    st.className = "st st-" + row.status.replace(" ", "-");
    document.body.dataset.status = row.status;
    ended = !!d.end || ["finished", "error", "timed out", "interrupted"].indexOf(row.status) >= 0;
    $("clock").textContent = d.end ? "ended after " + (d.end.t || 0).toFixed(1) + " s (" + d.end.reason + ")" : "";
    const probs = $("problems");
    probs.textContent = d.problem && d.problem.indexOf("no trajectory") < 0 ? d.problem : (row.status === "unreadable" ? row.detail : "");
  }
  function poll() {
    const from = calls.length;
    fetch("/api/episode?" + q + "&from=" + from, { headers: etag ? { "If-None-Match": etag } : {}, cache: "no-store" })
      .then(function (r) {
        if (r.status === 304) return null;
        if (r.status === 404) {
          gone = true;
          $("problems").textContent = "This episode's folder is gone (deleted or moved); the page shows what was read before.";
          document.body.dataset.gone = "1";
          return null;
        }
        if (!r.ok) throw new Error("HTTP " + r.status);
        etag = r.headers.get("ETag");
        return r.json();
      })
      .then(function (d) {
        $("conn").textContent = "live"; $("conn").className = "note";
        if (!d) return;
        if (gone) { gone = false; delete document.body.dataset.gone; }
        if (generation !== null && d.generation !== generation) {
          // the recording was removed or replaced: keep what was shown until a new one has begun
          if (!d.part_ids) { $("problems").textContent = "The recording was removed; waiting for a new one."; return; }
          reset(); generation = d.generation; etag = null; return;
        }
        generation = d.generation;
        if (d.start !== undefined && d.start !== calls.length) { reset(); etag = null; return; }
        showStatus(d.row, d);
        showTask(d);
        if (!d.part_ids) return;
        if (!states.length) states.push({ call: null, seq: 0, tool: "", t: 0, poses: d.initial_poses });
        const before = states.length;
        d.calls.forEach(function (c) {
          const i = calls.length;
          calls.push(c);
          if (c.poses) states.push({ call: i, seq: c.seq, tool: c.tool, t: c.t, poses: c.poses });
          addCall(c, i);
        });
        $("n-calls").textContent = String(calls.length);
        document.body.dataset.calls = String(calls.length);
        slider.max = String(states.length - 1);
        if (parts && !plotting) buildPlot();
        if (parts && (states.length !== before || shown < 0)) show(follow.checked ? states.length - 1 : shown);
        else if (scoreMode && ended) askScores();
      })
      .catch(function (err) { $("conn").textContent = "the viewer is not answering (" + err.message + ")"; $("conn").className = "down"; })
      .then(function () { setTimeout(poll, POLL_MS); });
  }
  slider.addEventListener("input", function () { follow.checked = false; show(parseInt(slider.value, 10)); });
  follow.addEventListener("change", function () { if (follow.checked) show(states.length - 1); });
  $("ghost").addEventListener("change", showScore);
  loadScene();
  poll();
})();
