// Sortable tables of the AssemblyWorld report: click a header to sort by that column
// (numbers by the value in data-v, other cells by text; empty values last), click again to reverse.
(function () {
  "use strict";
  function key(td) {
    const v = td.dataset.v;
    if (v !== undefined && v !== "") {
      const x = parseFloat(v);
      if (!Number.isNaN(x)) return { num: true, x: x };
    }
    const t = td.textContent.trim();
    return { num: false, x: t, empty: t === "" || t === "\u2013" };
  }
  function compare(a, b) {
    if (a.empty !== b.empty) return a.empty ? 1 : -1;
    if (a.num && b.num) return a.x - b.x;
    if (a.num !== b.num) return a.num ? -1 : 1;
    return String(a.x).localeCompare(String(b.x), undefined, { numeric: true });
  }
  function sortBy(table, th, col) {
    const body = table.tBodies[0];
    if (!body) return;
    const dir = th.getAttribute("aria-sort") === "ascending" ? -1 : 1;
    for (const h of table.tHead.rows[0].cells) h.removeAttribute("aria-sort");
    th.setAttribute("aria-sort", dir === 1 ? "ascending" : "descending");
    const rows = Array.from(body.rows).map(function (r, i) { return { r: r, i: i, k: key(r.cells[col]) }; });
    rows.sort(function (a, b) {
      const c = compare(a.k, b.k);
      if (a.k.empty || b.k.empty) return c || a.i - b.i; // empty values stay last in both directions
      return dir * c || a.i - b.i;
    });
    for (const x of rows) body.appendChild(x.r);
  }
  document.querySelectorAll("table.sortable").forEach(function (table) {
    if (!table.tHead) return;
    Array.from(table.tHead.rows[0].cells).forEach(function (th, col) {
      th.tabIndex = 0;
      th.title = "sort";
      th.addEventListener("click", function () { sortBy(table, th, col); });
      th.addEventListener("keydown", function (e) { if (e.key === "Enter") sortBy(table, th, col); });
    });
  });
})();
