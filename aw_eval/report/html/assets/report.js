// Sortable tables of the AssemblyWorld report: click a header (or press Enter on it) to sort by
// that column, click again to reverse. Cells that carry data-v (numeric columns) sort by that
// number, other cells by their text in natural order ("oracle-noise0.5" before "oracle-noise1.5");
// numbers come before text. Cells without a value (an empty data-v, no text, a dash) stay last in
// both directions, and ties keep the table's original order: every sort is stable and the same
// click always gives the same order.
(function () {
  "use strict";
  const collator = new Intl.Collator(undefined, { numeric: true, sensitivity: "base" });
  const NUMBER = 0, TEXT = 1, EMPTY = 2;
  const original = new WeakMap(); // row -> its position when the page was built

  function key(td) {
    if (!td) return { kind: EMPTY };
    if (td.hasAttribute("data-v")) {
      const x = parseFloat(td.getAttribute("data-v"));
      return Number.isNaN(x) ? { kind: EMPTY } : { kind: NUMBER, x: x };
    }
    const t = td.textContent.trim();
    return t === "" || t === "\u2013" ? { kind: EMPTY } : { kind: TEXT, x: t };
  }
  function compare(a, b) {
    if (a.kind !== b.kind) return a.kind - b.kind;
    if (a.kind === NUMBER) return a.x - b.x;
    if (a.kind === TEXT) return collator.compare(a.x, b.x) || (a.x < b.x ? -1 : a.x > b.x ? 1 : 0);
    return 0;
  }
  function sortBy(table, th, col) {
    const body = table.tBodies[0];
    if (!body) return;
    const dir = th.getAttribute("aria-sort") === "ascending" ? -1 : 1;
    for (const h of table.tHead.rows[0].cells) h.removeAttribute("aria-sort");
    th.setAttribute("aria-sort", dir === 1 ? "ascending" : "descending");
    const rows = Array.from(body.rows).map(function (r) { return { r: r, i: original.get(r), k: key(r.cells[col]) }; });
    rows.sort(function (a, b) {
      const c = compare(a.k, b.k);
      if (a.k.kind === EMPTY || b.k.kind === EMPTY) return c || a.i - b.i;
      return dir * c || a.i - b.i;
    });
    for (const x of rows) body.appendChild(x.r);
  }
  document.querySelectorAll("table.sortable").forEach(function (table) {
    if (!table.tHead || !table.tBodies[0]) return;
    Array.from(table.tBodies[0].rows).forEach(function (r, i) { original.set(r, i); });
    Array.from(table.tHead.rows[0].cells).forEach(function (th, col) {
      th.tabIndex = 0;
      th.title = "sort";
      th.addEventListener("click", function () { sortBy(table, th, col); });
      th.addEventListener("keydown", function (e) { if (e.key === "Enter") sortBy(table, th, col); });
    });
  });

  // A link to a folded section (or into one) opens it.
  function openTarget() {
    const id = decodeURIComponent(location.hash.slice(1));
    const el = id && document.getElementById(id);
    const fold = el && el.closest("details");
    if (fold) fold.open = true;
  }
  window.addEventListener("hashchange", openTarget);
  document.querySelectorAll('a[href^="#"]').forEach(function (a) {
    a.addEventListener("click", function () { setTimeout(openTarget); }); // the same link again: no hashchange
  });
  openTarget();
})();
