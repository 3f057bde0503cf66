/* plantcheck web page helpers: sortable tables, uPlot trends, PV(OP) plot, stiction chart. */
"use strict";
const plantcheck = (() => {
  const COLORS = { sp: "#888", pv: "#1565c0", op: "#c62828", mv: "#2e7d32" };
  const LABELS = { sp: "SP", pv: "PV", op: "OP", mv: "MV" };

  function cellValue(row, key, numeric) {
    const td = row.querySelector(`td[data-key="${key}"]`);
    if (!td) return numeric ? -Infinity : "";
    const raw = td.dataset.sort !== undefined ? td.dataset.sort : td.textContent.trim();
    if (numeric || td.dataset.sort !== undefined) {
      const x = parseFloat(raw);
      return Number.isFinite(x) ? x : -Infinity;
    }
    return raw.toLowerCase();
  }

  /* Sort a table's body by the column ``key`` (``-key``: descending). */
  function sortBy(table, spec) {
    const desc = spec.startsWith("-");
    const key = desc ? spec.slice(1) : spec;
    const th = table.querySelector(`th[data-key="${key}"]`);
    if (!th) return;
    const numeric = th.dataset.num === "1";
    const body = table.tBodies[0];
    const rows = Array.from(body.rows);
    rows.sort((a, b) => {
      const x = cellValue(a, key, numeric), y = cellValue(b, key, numeric);
      const c = x < y ? -1 : x > y ? 1 : 0;
      return desc ? -c : c;
    });
    rows.forEach((r) => body.appendChild(r));
    table.querySelectorAll("th").forEach((h) => h.removeAttribute("aria-sort"));
    th.setAttribute("aria-sort", desc ? "descending" : "ascending");
    table.dataset.sortedBy = spec;
  }

  /* Click a header to sort (again to reverse); ``#sort=key`` in the URL sorts on load. */
  function sortable(table) {
    if (!table) return;
    table.querySelectorAll("th[data-key]").forEach((th) => {
      th.addEventListener("click", () => {
        const key = th.dataset.key;
        const spec = table.dataset.sortedBy === key ? "-" + key : key;
        sortBy(table, spec);
        history.replaceState(null, "", "#sort=" + spec);
      });
    });
    const m = location.hash.match(/sort=(-?[\w]+)/);
    if (m) sortBy(table, m[1]);
  }

  function autoRefresh(seconds) {
    setTimeout(() => location.reload(), seconds * 1000);
  }

  /* Every axis and legend in UTC, 24-hour, as the tables (issue 47: the charts were in the
     browser's local 12-hour time). */
  const UTC = {
    tzDate: (ts) => uPlot.tzDate(new Date(ts * 1e3), "Etc/UTC"),
    fmtDate: (tpl) => uPlot.fmtDate(tpl.replace(/\{h\}/g, "{HH}").replace(/\s*\{aa?\}/g, "")
      .replace("{M}/{D}/{YY}", "{YYYY}-{MM}-{DD}").replace("{M}/{D}", "{MM}-{DD}")),
  };

  function width(el) {
    return Math.max(320, Math.min(1100, (el.parentElement || document.body).clientWidth - 20));
  }

  /* Time trends of the given signals (uPlot); x in POSIX seconds. */
  function trends(el, data, signals, title) {
    const present = signals.filter((s) => Array.isArray(data[s]));
    if (!el || !present.length || !data.t.length) {
      if (el) el.textContent = "No samples stored for this window yet.";
      return null;
    }
    const opts = {
      ...UTC,
      title: title + " (UTC)", width: width(el), height: 260,
      scales: { x: { time: true } },
      series: [{}].concat(present.map((s) => ({ label: LABELS[s], stroke: COLORS[s], width: 1.2 }))),
    };
    // the x axis' tick labels as drawn, for the page's tests (uPlot draws them on a canvas)
    opts.hooks = { draw: [(u) => { el.dataset.xLabels = (u.axes[0]._values || []).join("|"); }] };
    const u = new uPlot(opts, [data.t].concat(present.map((s) => data[s])), el);
    el.dataset.rendered = "true";
    el.dataset.points = String(data.t.length);
    return u;
  }

  /* PV against OP on a canvas: the shape tells a sticky valve (parallelogram) from a linear one. */
  function pvop(canvas, op, pv) {
    if (!canvas) return;
    const ctx = canvas.getContext("2d");
    const pts = [];
    for (let i = 0; i < Math.min(op.length, pv.length); i++) {
      if (op[i] !== null && pv[i] !== null) pts.push([op[i], pv[i]]);
    }
    ctx.fillStyle = "#fff"; ctx.fillRect(0, 0, canvas.width, canvas.height);
    if (pts.length < 2) { ctx.fillStyle = "#333"; ctx.fillText("no data", 20, 20); return; }
    const xs = pts.map((p) => p[0]), ys = pts.map((p) => p[1]);
    const x0 = Math.min(...xs), x1 = Math.max(...xs), y0 = Math.min(...ys), y1 = Math.max(...ys);
    const pad = 40, W = canvas.width - 2 * pad, H = canvas.height - 2 * pad;
    const sx = (x) => pad + (x1 > x0 ? (x - x0) / (x1 - x0) : 0.5) * W;
    const sy = (y) => pad + H - (y1 > y0 ? (y - y0) / (y1 - y0) : 0.5) * H;
    ctx.strokeStyle = "#999"; ctx.strokeRect(pad, pad, W, H);
    ctx.strokeStyle = "rgba(21,101,192,0.35)"; ctx.beginPath();
    pts.forEach((p, i) => (i ? ctx.lineTo(sx(p[0]), sy(p[1])) : ctx.moveTo(sx(p[0]), sy(p[1]))));
    ctx.stroke();
    ctx.fillStyle = "#333"; ctx.font = "12px sans-serif";
    ctx.fillText(`OP ${x0.toFixed(1)} … ${x1.toFixed(1)} %`, pad, canvas.height - 10);
    ctx.save(); ctx.translate(12, pad + H); ctx.rotate(-Math.PI / 2);
    ctx.fillText(`PV ${y0.toFixed(2)} … ${y1.toFixed(2)}`, 0, 0); ctx.restore();
    canvas.dataset.rendered = "true";
    canvas.dataset.points = String(pts.length);
  }

  /* One valve's S over time, its limit, and the projection to the limit (uPlot). The trend's
     method (its reliable estimates) is drawn filled; other methods and unreliable estimates as
     open marks of their own series, so that methods are never mixed silently. */
  function stiction(el, v) {
    const est = v.estimates.map((e) => [Date.parse(e.time) / 1000, e.S,
      e.method === v.trend_method && e.reliable !== false]);
    if (!est.length) return null;
    const cross = v.projected_crossing ? Date.parse(v.projected_crossing) / 1000 : null;
    const t = est.map((e) => e[0]);
    // the axis spans the estimates and a quarter of that (at least a day) ahead: a crossing
    // projected years away is drawn as the trend toward it, not as a years-long axis
    const last = t[t.length - 1];
    const horizon = last + Math.max(86400, 0.25 * (last - t[0]));
    let projS = null;
    if (cross !== null && cross > last && cross <= horizon) {
      t.push(cross); projS = v.limit;
    } else if (v.slope_per_week !== null && v.current_S !== null && v.slope_per_week > 0) {
      t.push(horizon); projS = v.current_S + v.slope_per_week * (horizon - last) / 604800;
    }
    const S = t.map((_, i) => (i < est.length && est[i][2] ? est[i][1] : null));
    const other = t.map((_, i) => (i < est.length && !est[i][2] ? est[i][1] : null));
    const limit = t.map(() => v.limit);
    const proj = t.map(() => null);
    if (projS !== null && t.length > est.length) {
      proj[est.length - 1] = v.current_S; proj[t.length - 1] = projS;
    }
    const u = new uPlot({
      ...UTC,
      title: `${v.loop}: S (% of travel), UTC`, width: width(el), height: 220,
      scales: { x: { time: true } },
      series: [{},
        { label: `S (${v.trend_method || "none"})`, stroke: "#c62828", width: 0, paths: () => null, points: { show: true, size: 6, fill: "#c62828" } },
        { label: "limit", stroke: "#555", dash: [6, 4] },
        { label: "projection", stroke: "#ef6c00", dash: [2, 3], spanGaps: true },
        { label: "other methods, not in the trend", stroke: "#6a1b9a", width: 0, paths: () => null, points: { show: true, size: 6, fill: "#fff" } }],
    }, [t, S, limit, proj, other], el);
    el.dataset.rendered = "true";
    return u;
  }

  /* The retuning's prediction (issue 48): the identified process under the present and the
     proposed controller, after a unit set-point step or a load step worth one PV unit. */
  function retuning(el, pred, which) {
    const cur = pred.current_response, prop = pred.proposed_response;
    if (!el || !prop) return null;
    const series = [{}, { label: "proposed", stroke: "#2e7d32", width: 1.6 }];
    const rows = [prop.t_s, prop[which]];
    if (cur) {
      // the present controller's response on its own time axis, read at the proposal's times
      series.push({ label: "present", stroke: "#c62828", width: 1.2 });
      rows.push(prop.t_s.map((t) => {
        let i = cur.t_s.findIndex((x) => x >= t);
        return i < 0 ? null : cur[which][i];
      }));
    }
    const title = which === "sp" ? "Predicted PV after a unit set-point step"
      : "Predicted PV after a load step worth one PV unit";
    const u = new uPlot({
      title, width: width(el), height: 220, scales: { x: { time: false } },
      axes: [{ label: "seconds after the step" }, {}], series,
    }, rows, el);
    el.dataset.rendered = "true";
    return u;
  }

  /* The margins plot (issue 48): |S(jω)| of the present and the proposed loop against
     frequency, log-log; the peak is Ms, and the dashed line is the usual limit Ms = 2. */
  function margins(el, pred) {
    const prop = pred.proposed_sensitivity, cur = pred.current_sensitivity;
    if (!el || !prop) return null;
    const w = prop.w_rad_s;
    const series = [{}, { label: "proposed |S|", stroke: "#2e7d32", width: 1.6 }];
    const rows = [w, prop.mag];
    if (cur) {
      series.push({ label: "present |S|", stroke: "#c62828", width: 1.2 });
      rows.push(w.map((x) => {  // the present loop's |S| read at the proposal's frequencies
        const i = cur.w_rad_s.findIndex((v) => v >= x);
        return i < 0 ? null : cur.mag[i];
      }));
    }
    series.push({ label: "Ms = 2", stroke: "#757575", dash: [6, 4], width: 1 });
    rows.push(w.map(() => 2));
    const u = new uPlot({
      title: "Sensitivity |S(jω)|: the peak is Ms, above 1 a disturbance is amplified",
      width: width(el), height: 220,
      scales: { x: { time: false, distr: 3 }, y: { distr: 3 } },
      axes: [{ label: "ω (rad/s)" }, {}], series,
    }, rows, el);
    el.dataset.rendered = "true";
    return u;
  }

  return { sortable, sortBy, autoRefresh, trends, pvop, stiction, retuning, margins };
})();
