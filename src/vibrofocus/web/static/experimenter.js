// Experimenter page: participants, calibration, preview, sessions, live answers, export.
// Authentication is the HttpOnly cookie set when the page was opened with ?token=.
"use strict";

(() => {
  const $ = (id) => document.getElementById(id);
  let selectedSession = null;

  function flash(text, isError = false) {
    const el = $("flash");
    el.textContent = text;
    el.className = isError ? "error" : "";
  }

  async function api(path, options = {}) {
    const res = await fetch(path, {
      credentials: "same-origin",
      headers: { "Content-Type": "application/json" },
      ...options,
    });
    if (!res.ok) {
      const detail = await res.json().catch(() => ({}));
      throw new Error(detail.detail || `${res.status} ${res.statusText}`);
    }
    return res.json();
  }

  function el(tag, attrs = {}, ...children) {
    const node = document.createElement(tag);
    for (const [k, v] of Object.entries(attrs)) {
      if (k === "onclick") node.addEventListener("click", v);
      else node.setAttribute(k, v);
    }
    for (const c of children) node.append(c);
    return node;
  }

  // ---------------------------------------------------------------- participants
  let participants = [];
  async function loadParticipants(select = null) {
    participants = await api("/api/participants");
    const sel = $("participant");
    const keep = select ?? sel.value;
    sel.replaceChildren(...participants.map((p) =>
      el("option", { value: p.participant_id }, p.participant_id + (p.simulated ? " (simulated)" : ""))));
    if (keep && participants.some((p) => p.participant_id === keep)) sel.value = keep;
    onParticipant();
  }

  function onParticipant() {
    const p = participants.find((x) => x.participant_id === $("participant").value);
    const cals = p ? p.calibrations : [];
    const sel = $("calibration");
    const keep = sel.value;
    sel.replaceChildren(el("option", { value: "" }, cals.length ? "— none (dry run) —" : "— none yet —"),
      ...cals.map((c) => el("option", { value: c.calibration_id }, `#${c.calibration_id} · ${c.created_at.slice(0, 19).replace("T", " ")}`)));
    if (cals.some((c) => String(c.calibration_id) === keep)) sel.value = keep;
    else if (cals.length) sel.value = cals[cals.length - 1].calibration_id;
    onCalibration();
    loadSessions();
  }

  $("participant").addEventListener("change", onParticipant);
  $("new-participant").addEventListener("submit", async (ev) => {
    ev.preventDefault();
    const id = $("new-participant-id").value.trim();
    try {
      await api("/api/participants", { method: "POST", body: JSON.stringify({ participant_id: id, simulated: $("new-participant-sim").checked }) });
      $("new-participant-id").value = "";
      await loadParticipants(id);
      flash(`Participant ${id} added.`);
    } catch (e) { flash(e.message, true); }
  });

  // ---------------------------------------------------------------- rig and calibration
  async function loadRigs() {
    const rigs = await api("/api/rigs");
    $("rig").replaceChildren(...rigs.kinds.map((k) => el("option", { value: k }, k === rigs.default ? rigs.label : k)));
    $("rig").value = rigs.default;
    $("rig-label").textContent = rigs.label;
  }

  function onCalibration() {
    const id = $("calibration").value;
    const img = $("cal-figure");
    if (id) {
      img.src = `/api/calibrations/${id}/figure.png`;
      img.hidden = false;
      $("preview-message").textContent = "";
    } else {
      img.hidden = true;
      img.removeAttribute("src");
      $("preview-message").textContent = "Needs a calibration.";
    }
  }
  $("calibration").addEventListener("change", onCalibration);

  function rigQuery() {
    return `rig=${encodeURIComponent($("rig").value)}&seed=${Number($("rig-seed").value) || 0}`;
  }

  async function readStraps() {
    // Strap forces before calibrating: a loose strap changes the coupling to the skin.
    const res = await fetch(`/api/rigs/straps?${rigQuery()}`, { credentials: "same-origin" });
    const d = await res.json().catch(() => ({}));
    const msg = $("strap-message");
    msg.textContent = res.ok ? `Strap forces: ${d.message}` : (d.detail || "The strap forces could not be read.");
    msg.className = res.ok && !d.ok ? "error" : "muted";
    return res.ok ? d : null;
  }
  $("straps").addEventListener("click", readStraps);

  let calJob = null;
  $("cal-continue").addEventListener("click", async () => {
    if (!calJob) return;
    $("cal-continue").disabled = true;
    try { await api(`/api/calibrations/jobs/${calJob}/continue`, { method: "POST" }); }
    catch (e) { flash(e.message, true); }
  });
  $("cal-cancel").addEventListener("click", async () => {
    if (!calJob) return;
    try { await api(`/api/calibrations/jobs/${calJob}/cancel`, { method: "POST" }); }
    catch (e) { flash(e.message, true); }
  });

  $("calibrate").addEventListener("click", async () => {
    const pid = $("participant").value;
    if (!pid) { flash("Add or pick a participant first.", true); return; }
    try {
      const { job_id } = await api("/api/calibrations", { method: "POST", body: JSON.stringify({
        participant_id: pid, rig: $("rig").value, seed: Number($("rig-seed").value) || 0 }) });
      calJob = job_id;
      $("calibrate").disabled = true;
      $("cal-cancel").hidden = false;
      for (;;) {
        const job = await api(`/api/calibrations/jobs/${job_id}`);
        $("cal-progress").value = job.progress;
        $("cal-message").textContent = `${Math.round(job.progress * 100)} % · ${job.message}`;
        if (job.straps) {
          $("strap-message").textContent = `Strap forces: ${job.straps.message}`;
          $("strap-message").className = job.straps.ok ? "muted" : "error";
        }
        const waiting = job.status === "waiting";
        if (waiting && $("cal-prompt").hidden) $("cal-continue").disabled = false;
        $("cal-prompt").hidden = !waiting;
        $("cal-prompt-text").textContent = waiting ? job.prompt : "";
        if (job.status === "done") {
          flash(`Calibration #${job.calibration_id} saved.`);
          await loadParticipants(pid);
          $("calibration").value = job.calibration_id;
          onCalibration();
          break;
        }
        if (job.status === "failed") { flash(`Calibration failed: ${job.error}`, true); break; }
        if (job.status === "cancelled") { flash("Calibration cancelled; nothing was saved."); break; }
        await new Promise((r) => setTimeout(r, 500));
      }
    } catch (e) { flash(e.message, true); }
    calJob = null;
    $("cal-prompt").hidden = true;
    $("cal-cancel").hidden = true;
    $("calibrate").disabled = false;
  });

  // ---------------------------------------------------------------- preview
  $("location").replaceChildren(...Array.from({ length: 9 }, (_, i) => el("option", { value: i + 1 }, String(i + 1))));
  $("location").value = "5";
  $("preview").addEventListener("click", async () => {
    const id = $("calibration").value;
    if (!id) { flash("Calibrate first (or pick a calibration) to preview.", true); return; }
    const url = `/api/preview.png?calibration_id=${id}&method=${$("method").value}&location=${$("location").value}`;
    $("preview-message").textContent = "Rendering…";
    const res = await fetch(url, { credentials: "same-origin" });
    if (!res.ok) {
      const d = await res.json().catch(() => ({}));
      $("preview-message").textContent = d.detail || res.statusText;
      return;
    }
    const img = $("preview-figure");
    img.src = URL.createObjectURL(await res.blob());
    img.hidden = false;
    $("preview-message").textContent = "";
  });

  // ---------------------------------------------------------------- sessions
  async function loadSessions() {
    const pid = $("participant").value;
    let sessions = [];
    try { sessions = await api(`/api/sessions${pid ? `?participant_id=${encodeURIComponent(pid)}` : ""}`); }
    catch (e) { flash(e.message, true); return; }
    // Rows are updated in place and rebuilt only when a status changes, so that the
    // control buttons do not move or vanish under the experimenter's pointer.
    const tbody = $("sessions").querySelector("tbody");
    const existing = new Map(Array.from(tbody.children, (tr) => [tr.dataset.session, tr]));
    const rows = sessions.slice().reverse().map((s) => {
      const live = s.live && s.live.waiting_for_page ? "waiting for the participant page"
        : s.live ? `${s.live.state}${s.live.trial_index !== null && s.live.trial_index !== undefined ? " · trial " + s.live.trial_index : ""}` : "—";
      let tr = existing.get(String(s.session_id));
      if (!tr || tr.dataset.status !== s.status) tr = sessionRow(s);
      tr.querySelector(".progress").textContent = `${s.n_answered} / ${s.n_trials}`;
      tr.querySelector(".live").textContent = live;
      tr.classList.toggle("selected", s.session_id === selectedSession);
      return tr;
    });
    if (rows.length !== tbody.children.length || rows.some((tr, i) => tbody.children[i] !== tr)) tbody.replaceChildren(...rows);
    if (selectedSession === null && sessions.length) selectedSession = sessions[sessions.length - 1].session_id;
    loadLive();
  }

  function sessionRow(s) {
    const link = el("a", { href: s.participant_url, target: "_blank", rel: "noopener" }, "open");
    const copy = el("button", { class: "small", onclick: (ev) => {
      ev.stopPropagation();
      navigator.clipboard?.writeText(new URL(s.participant_url, location.href).href);
      flash("Participant link copied.");
    } }, "copy");
    const controls = el("span", { class: "controls" });
    const act = (label, action) => controls.append(el("button", { class: "small", "data-action": action,
      onclick: async (ev) => {
        ev.stopPropagation();
        try { await api(`/api/sessions/${s.session_id}/${action}`, { method: "POST" }); flash(`Session ${s.session_id}: ${action}.`); }
        catch (e) { flash(e.message, true); }
        selectedSession = s.session_id;
        loadSessions();
      } }, label));
    if (s.status === "planned") act("Start", "start");
    if (s.status === "running") act("Pause", "pause");
    if (s.status === "paused" || s.status === "aborted") act("Resume", "resume");
    if (s.status === "running" || s.status === "paused") act("Stop", "stop");
    const tr = el("tr", { "data-session": s.session_id, "data-status": s.status },
      el("td", {}, String(s.session_id)), el("td", {}, s.participant_id), el("td", {}, String(s.study)),
      el("td", { class: `status ${s.status}` }, s.status + (s.dry_run ? " · dry run" : "")), el("td", { class: "progress" }), el("td", { class: "live" }),
      el("td", {}, link, " ", copy), el("td", {}, controls));
    tr.addEventListener("click", () => { selectedSession = s.session_id; loadSessions(); });
    return tr;
  }

  $("new-session").addEventListener("submit", async (ev) => {
    ev.preventDefault();
    const pid = $("participant").value;
    if (!pid) { flash("Add or pick a participant first.", true); return; }
    const cal = $("calibration").value;
    try {
      const s = await api("/api/sessions", { method: "POST", body: JSON.stringify({
        participant_id: pid, study: Number($("study").value), calibration_id: cal ? Number(cal) : null,
        rig: $("rig").value, rig_seed: Number($("rig-seed").value) || 0,
        repetitions: Number($("repetitions").value), n_training: Number($("n-training").value) }) });
      selectedSession = s.session_id;
      flash(`Session ${s.session_id} planned (${s.n_trials} trials)${cal ? "" : " — no calibration: a dry run, nothing is played"}.`);
      loadSessions();
    } catch (e) { flash(e.message, true); }
  });

  async function loadLive() {
    if (selectedSession === null) return;
    let s;
    try { s = await api(`/api/sessions/${selectedSession}`); } catch { return; }
    $("live-title").textContent = `session ${s.session_id} · study ${s.study} · ${s.status}` +
      (s.live ? ` · ${s.live.state}` : "") + (s.live && s.live.error ? ` · ${s.live.error}` : "");
    $("live-progress").value = s.n_trials ? s.n_answered / s.n_trials : 0;
    const rows = s.answers.slice().reverse().map((a) => el("tr", { class: a.response.includes(a.target) ? "hit" : "" },
      el("td", {}, String(a.trial)), el("td", {}, a.phase), el("td", {}, a.method), el("td", {}, String(a.target)),
      el("td", {}, a.response.join(" ")), el("td", {}, a.rt_s.toFixed(3)), el("td", {}, a.recorded_at.slice(11, 19))));
    $("answers").querySelector("tbody").replaceChildren(...rows);
  }

  // ---------------------------------------------------------------- export and analysis
  $("analyze").addEventListener("click", async () => {
    try {
      let job = await api("/api/analysis", { method: "POST", body: "{}" });
      $("analysis-message").textContent = `Analysing ${job.rows} trials…`;
      while (job.status === "running") {
        await new Promise((r) => setTimeout(r, 1000));
        job = await api(`/api/analysis/${job.name}`);
      }
      const msg = $("analysis-message");
      if (job.status === "done") msg.replaceChildren("Report ready: ", el("a", { href: job.url, target: "_blank" }, "open report.html"));
      else msg.textContent = `Analysis failed: ${job.log.split("\n").filter(Boolean).pop() || "see the server log"}`;
    } catch (e) { $("analysis-message").textContent = e.message; }
  });

  // ---------------------------------------------------------------- start
  (async () => {
    try { await loadRigs(); await loadParticipants(); }
    catch (e) { flash(e.message, true); }
    setInterval(loadSessions, 1500);
  })();
})();
