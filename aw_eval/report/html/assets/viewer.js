// The 3D view of a task's runs (plotly mesh3d, loaded on first use from the report's folder):
// each system's recorded states over the target, a slider over the states, a system switcher;
// and the runs' tool-call lists. A task's data file, loaded when one of them opens, calls
// AWViewer.register(taskId, data); poses are [x, y, z, qw, qx, qy, qz]. AWViewer.place and
// AWViewer.mesh draw a part at a pose for other pages (aw-view's live episode page).
(function () {
  "use strict";
  const PLOTLY_SRC = document.currentScript.dataset.plotly;
  const data = {};
  const waiting = {};
  window.AWViewer = {
    register: function (id, d) {
      data[id] = d;
      (waiting[id] || []).forEach(function (f) { f(d); });
      delete waiting[id];
    },
  };
  function loadScript(src) {
    return new Promise(function (resolve, reject) {
      const s = document.createElement("script");
      s.src = src;
      s.onload = resolve;
      s.onerror = function () { reject(new Error("cannot load " + src)); };
      document.head.appendChild(s);
    });
  }
  let plotlyLoaded = null;
  function plotly() {
    if (!plotlyLoaded) plotlyLoaded = window.Plotly ? Promise.resolve() : loadScript(PLOTLY_SRC);
    return plotlyLoaded;
  }
  function taskData(id, src) {
    if (data[id]) return Promise.resolve(data[id]);
    return new Promise(function (resolve, reject) {
      (waiting[id] = waiting[id] || []).push(resolve);
      loadScript(src).catch(reject);
    });
  }
  function place(v, pose) {
    const x = pose[0], y = pose[1], z = pose[2];
    let w = pose[3], a = pose[4], b = pose[5], c = pose[6];
    const n = Math.hypot(w, a, b, c) || 1;
    w /= n; a /= n; b /= n; c /= n;
    const r = [1 - 2 * (b * b + c * c), 2 * (a * b - w * c), 2 * (a * c + w * b),
               2 * (a * b + w * c), 1 - 2 * (a * a + c * c), 2 * (b * c - w * a),
               2 * (a * c - w * b), 2 * (b * c + w * a), 1 - 2 * (a * a + b * b)];
    const m = v.length / 3, X = new Array(m), Y = new Array(m), Z = new Array(m);
    for (let i = 0; i < m; i++) {
      const p = v[3 * i], q = v[3 * i + 1], s = v[3 * i + 2];
      X[i] = r[0] * p + r[1] * q + r[2] * s + x;
      Y[i] = r[3] * p + r[4] * q + r[5] * s + y;
      Z[i] = r[6] * p + r[7] * q + r[8] * s + z;
    }
    return [X, Y, Z];
  }
  function faces(f) {
    const n = f.length / 3, I = new Array(n), J = new Array(n), K = new Array(n);
    for (let t = 0; t < n; t++) { I[t] = f[3 * t]; J[t] = f[3 * t + 1]; K[t] = f[3 * t + 2]; }
    return [I, J, K];
  }
  function mesh(part, poses, k, opacity, name) {
    const xyz = place(part.v, poses[k]), ijk = faces(part.f);
    return { type: "mesh3d", x: xyz[0], y: xyz[1], z: xyz[2], i: ijk[0], j: ijk[1], k: ijk[2], color: part.color,
             opacity: opacity, flatshading: true, name: name, hoverinfo: "name", showscale: false };
  }
  window.AWViewer.place = place;
  window.AWViewer.mesh = mesh;
  function fmt(x, d) { return x === null || x === undefined ? "\u2013" : x.toFixed(d); }
  function build(box, d) {
    const systems = Object.keys(d.systems);
    box.innerHTML = "";
    const bar = document.createElement("div");
    bar.className = "viewer-bar";
    const select = document.createElement("select");
    select.className = "viewer-system";
    systems.forEach(function (s) { const o = document.createElement("option"); o.value = s; o.textContent = s; select.appendChild(o); });
    const slider = document.createElement("input");
    slider.type = "range"; slider.min = "0"; slider.step = "1"; slider.className = "viewer-slider";
    const label = document.createElement("span");
    label.className = "viewer-label";
    const ghost = document.createElement("label");
    ghost.innerHTML = '<input type="checkbox" checked> target';
    bar.append("System ", select, " state ", slider, label, ghost);
    const plot = document.createElement("div");
    plot.className = "viewer-plot";
    box.append(bar, plot);
    const P = d.parts.length;
    const target = d.parts.map(function (p, i) { return mesh(p, d.target, i, 0.25, "target " + p.id); });
    function states() { return d.systems[select.value].states; }
    function statePoses(k) { return states()[k].poses; }
    function stateTraces(k) {
      const poses = statePoses(k);
      return d.parts.map(function (p, i) { return mesh(p, poses, i, 1.0, p.id); });
    }
    function show(k) {
      const st = states()[k];
      label.textContent = " " + (k + 1) + "/" + states().length + ": " + st.label + " \u00b7 PA " + fmt(st.pa, 1) + "% \u00b7 SCD " + fmt(st.scd, 2);
      const poses = st.poses, X = [], Y = [], Z = [];
      d.parts.forEach(function (p, i) { const xyz = place(p.v, poses[i]); X.push(xyz[0]); Y.push(xyz[1]); Z.push(xyz[2]); });
      const idx = d.parts.map(function (_, i) { return P + i; });
      return window.Plotly.restyle(plot, { x: X, y: Y, z: Z }, idx).then(function () { box.dataset.state = String(k); });
    }
    function reset() {
      slider.max = String(states().length - 1);
      slider.value = slider.max;
      return show(states().length - 1);
    }
    const last = states().length - 1;
    const layout = { margin: { l: 0, r: 0, t: 0, b: 0 }, showlegend: false, uirevision: "keep",
                     scene: { aspectmode: "data", xaxis: { title: "x" }, yaxis: { title: "y" }, zaxis: { title: "z" } } };
    return window.Plotly.newPlot(plot, target.concat(stateTraces(last)), layout, { displaylogo: false, responsive: true })
      .then(function () {
        slider.addEventListener("input", function () { show(parseInt(slider.value, 10)); });
        select.addEventListener("change", reset);
        ghost.firstChild.addEventListener("change", function (e) {
          window.Plotly.restyle(plot, { visible: e.target.checked }, target.map(function (_, i) { return i; }));
        });
        return reset();
      })
      .then(function () { box.dataset.ready = "1"; });
  }
  function fillCalls(details, d) {
    const sys = d.systems[details.dataset.system];
    const ol = details.querySelector("ul.calls");
    sys.calls.forEach(function (c) {
      const li = document.createElement("li");
      li.className = c[4] ? "ok" : "err";
      const code = document.createElement("code");
      code.textContent = c[3];
      const tool = document.createElement("b");
      tool.textContent = c[2];
      li.append(c[0] + " \u00b7 " + c[1].toFixed(1) + " s ", tool, " ", code, " " + (c[4] ? "ok" : "error: " + c[5]));
      ol.appendChild(li);
    });
    if (sys.n_calls > sys.calls.length) {
      const li = document.createElement("li");
      li.textContent = "\u2026 and " + (sys.n_calls - sys.calls.length) + " more (trajectory.jsonl)";
      ol.appendChild(li);
    }
    details.dataset.ready = "1";
  }
  // tool-call lists are filled from the task's data file the first time they open
  document.addEventListener("toggle", function (e) {
    const details = e.target;
    if (!details.matches || !details.matches("details.calls") || !details.open || details.dataset.ready) return;
    taskData(details.dataset.task, details.dataset.src)
      .then(function (d) { if (!details.dataset.ready) fillCalls(details, d); })
      .catch(function (err) { details.querySelector("ul.calls").textContent = "could not load: " + err.message; });
  }, true);
  document.addEventListener("click", function (e) {
    const btn = e.target.closest("button.open3d");
    if (!btn) return;
    const box = btn.nextElementSibling;
    if (!box.hidden) { box.hidden = true; return; }
    box.hidden = false;
    if (box.dataset.ready) return;
    box.textContent = "loading\u2026";
    Promise.all([plotly(), taskData(btn.dataset.task, btn.dataset.src)])
      .then(function (r) { return build(box, r[1]); })
      .catch(function (err) { box.textContent = "The 3D view could not load: " + err.message; });
  });
})();
