// Experimenter page: participants, calibration, preview, sessions, live answers, export.
// Authentication is the HttpOnly cookie set when the page was opened with ?token=.
"use strict";

(() => {
  const $ = (id) => document.getElementById(id);
  let selectedSession = null;

  // A confirmation goes after a few seconds; an error stays until the next action (a
  // click on a control) or four times as long. Tests shorten the time.
  const FLASH_MS = window.vfFlashMs || 6000;
  let flashTimer = null;
  function flash(text, isError = false) {
    const el = $("flash");
    el.textContent = text;
    el.className = isError ? "error" : "";
    clearTimeout(flashTimer);
    flashTimer = text ? setTimeout(() => flash(""), isError ? 4 * FLASH_MS : FLASH_MS) : null;
  }
  document.addEventListener("click", (ev) => {
    if ($("flash").className === "error" && ev.target.closest("button, a, select, input")) flash("");
  }, true);

  function statusText(status) {
    return status >= 500
      ? `The server could not do this (error ${status}); the terminal running 'vibrofocus serve' says why.`
      : `The server refused this (error ${status}).`;
  }

  // The server may stop and start again (a restart, a crash) while this page stays open:
  // while it cannot be reached the page says so and shows no live state it cannot vouch
  // for; when it answers again, everything is read afresh. A server that no longer
  // knows this login (a new token) gets the login form at once.
  const UNREACHABLE = "The server cannot be reached: is 'vibrofocus serve' still running? Retrying…";
  let offline = false;
  function setOffline(value) {
    if (offline === value) return;
    offline = value;
    document.body.classList.toggle("offline", value);
    $("connection").hidden = !value;
    $("connection").textContent = value ? UNREACHABLE : "";
    if (value) {
      for (const td of document.querySelectorAll("#sessions td.live")) td.textContent = "unknown (server not reachable)";
      $("live-title").textContent = "· unknown while the server is not reachable";
    } else {
      flash("The server is back; the page has been refreshed.");
      loadRigs().then(() => loadParticipants()).catch((e) => flash(e.message, true));
    }
  }

  async function api(path, options = {}) {
    let res;
    try {
      res = await fetch(path, {
        credentials: "same-origin",
        headers: { "Content-Type": "application/json" },
        ...options,
      });
    } catch {
      setOffline(true);
      throw new Error(UNREACHABLE);
    }
    setOffline(false);
    if (res.status === 401) {
      // Logged out on the server (logout elsewhere, or a restart with a new token):
      // the page itself is now the login form.
      location.reload();
      throw new Error("Not logged in any more: log in again.");
    }
    if (!res.ok) {
      const detail = await res.json().catch(() => ({}));
      throw new Error(detail.detail || statusText(res.status));
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

  // The simulated forearm's seed; null (empty field): the server derives it from the participant id.
  function rigSeed() {
    const v = $("rig-seed").value.trim();
    return v === "" ? null : Number(v);
  }

  // ---------------------------------------------------------------- emergency stop
  async function emergencyStop() {
    try {
      const out = await api("/api/emergency-stop", { method: "POST" });
      flash("Stopped: " + (out.stopped.length ? out.stopped.join("; ") : "nothing was running") + ".", true);
    } catch (err) {
      flash("The emergency stop did not reach the server (" + err.message + "): switch the amplifier off.", true);
    }
  }
  // The button is a form's (it works without this script); with the script, the stop
  // is sent in the background and the page stays.
  $("emergency-form").addEventListener("submit", (ev) => { ev.preventDefault(); emergencyStop(); });
  let lastEscape = 0;
  document.addEventListener("keydown", (ev) => {
    if (ev.key !== "Escape") return;
    const now = Date.now();
    // One Esc closes an open "stop for good?" question (keeping the session); Esc twice
    // is the emergency stop, whether a question was open or not.
    if (pendingStop) pendingStop.cancel();
    if (now - lastEscape < 800) emergencyStop();
    lastEscape = now;
  });

  // ---------------------------------------------------------------- participants
  let participants = [];
  let participantsShown = false;
  let participantsQueue = Promise.resolve();
  function loadParticipants(select = null) {
    // One load at a time, in the order asked: a slow answer fetched before an add (the
    // page's first load, on a busy server) never shows its older list over the newer one.
    const run = participantsQueue.then(() => showParticipants(select));
    participantsQueue = run.catch(() => {});
    return run;
  }
  async function showParticipants(select) {
    participants = await api("/api/participants");
    const sel = $("participant");
    // The page opens on the newest participant who is a person; with none (a new database,
    // or one of simulate-study's models only) on "add a participant", never on a model's session.
    const people = participants.filter((p) => !p.simulated);
    const keep = select ?? (participantsShown ? sel.value : people.length ? people[people.length - 1].participant_id : "");
    sel.replaceChildren(el("option", { value: "" }, participants.length ? "— choose, or add one —" : "— none yet: add one —"),
      ...participants.map((p) => el("option", { value: p.participant_id }, p.participant_id + (p.simulated ? " (simulated)" : ""))));
    sel.value = keep && participants.some((p) => p.participant_id === keep) ? keep : "";
    // A new database opens on "add a participant", unless the experimenter has already put
    // the focus somewhere (a first list answered late must not take it from them).
    const untouched = !document.activeElement || document.activeElement === document.body;
    if (!participantsShown && !sel.value && untouched) $("new-participant-id").focus();
    participantsShown = true;
    onParticipant();
  }

  let shownParticipant = null;
  function onParticipant() {
    if ($("participant").value !== shownParticipant) {
      // Another participant: the live panel must not go on showing the last one's session.
      shownParticipant = $("participant").value;
      selectSession(null);
    }
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
    loadPlans();  // the plan list follows the rig
  }

  async function showFigure(url, img, message, busy) {
    // A figure is fetched first and shown only once it has arrived: a failure is said
    // in words, never shown as a broken image. Returns false if it failed.
    message.textContent = busy;
    const res = await fetch(url, { credentials: "same-origin" }).catch(() => null);
    if (!res || !res.ok) {
      const d = res ? await res.json().catch(() => ({})) : {};
      img.hidden = true;
      message.textContent = d.detail || (res ? statusText(res.status) : "The server cannot be reached.");
      return false;
    }
    if (img.src.startsWith("blob:")) URL.revokeObjectURL(img.src);
    img.src = URL.createObjectURL(await res.blob());
    img.hidden = false;
    message.textContent = "";
    return true;
  }

  let verdictsAsked = 0;  // only the latest selection's verdicts are shown
  async function showVerdicts(id) {
    const list = $("cal-verdicts");
    const asked = ++verdictsAsked;
    $("cal-override").checked = false;
    $("cal-override-label").hidden = true;
    if (!id) { list.hidden = true; list.replaceChildren(); return; }
    let q;
    try { q = await api(`/api/calibrations/${id}/quality`); } catch (e) { q = null; }
    if (asked !== verdictsAsked) return;
    if (!q) { list.replaceChildren(el("li", { class: "error" }, "The quality verdicts could not be read.")); list.hidden = false; return; }
    const items = q.verdicts.filter((v) => v.severity !== "info").map((v) =>
      el("li", { class: v.severity === "error" ? "error" : "warning" }, `${v.severity}: ${v.message}`));
    if (!items.length) items.push(el("li", { class: "muted" }, "Quality: no warnings or errors."));
    if (q.predicted && q.predicted.length) items.push(el("li", { class: "muted", id: "cal-predicted" },
      `Measured ${q.measured.length} of ${q.measured.length + q.predicted.length} points; H at point(s) ` +
      `${q.predicted.join(", ")} is predicted by the skin model fitted to them.`));
    else if (q.n_errors) items.unshift(el("li", { class: "error" },
      `${q.n_errors} error verdict(s): sessions on this calibration need 'use the calibration despite its errors'.`));
    list.replaceChildren(...items);
    list.hidden = false;
    $("cal-override-label").hidden = !q.n_errors;
  }

  function onCalibration() {
    const id = $("calibration").value;
    const img = $("cal-figure");
    $("preview-message").textContent = id ? "" : "A preview needs a calibration.";
    showVerdicts(id);
    if (id) {
      showFigure(`/api/calibrations/${id}/figure.png`, img, $("cal-figure-message"), "Loading the figure…");
      return;
    }
    img.hidden = true;
    const some = $("calibration").options.length > 1;
    $("cal-figure-message").textContent = calJob ? "Calibrating: the new calibration is shown when it is saved."
      : some ? "No calibration chosen: sessions planned now are dry runs (nothing is played)."
      : "No calibration yet: press Calibrate.";
  }
  $("calibration").addEventListener("change", onCalibration);

  function rigQuery() {
    const seed = rigSeed();
    return `rig=${encodeURIComponent($("rig").value)}` + (seed === null ? "" : `&seed=${seed}`);
  }

  async function readStraps() {
    // Strap forces before calibrating: a loose strap changes the coupling to the skin.
    const res = await fetch(`/api/rigs/straps?${rigQuery()}`, { credentials: "same-origin" }).catch(() => null);
    const msg = $("strap-message");
    if (res === null) { msg.textContent = UNREACHABLE; msg.className = "error"; return null; }
    const d = await res.json().catch(() => ({}));
    msg.textContent = res.ok ? `Strap forces: ${d.message}` : (d.detail || "The strap forces could not be read.");
    msg.className = res.ok && !d.ok ? "error" : "muted";
    return res.ok ? d : null;
  }
  $("straps").addEventListener("click", readStraps);

  // The plans offered: every point, or a subset with the rest predicted by the fitted model.
  let calPlans = [];
  function showPlan() {
    const plan = calPlans.find((p) => String(p.points ?? "") === $("cal-points").value);
    $("cal-plan").textContent = plan ? `Plan: ${plan.description}.` : "";
  }
  async function loadPlans() {
    let d;
    try { d = await api(`/api/calibrations/plans?${rigQuery()}`); } catch (e) { $("cal-plan").textContent = ""; return; }
    const keep = $("cal-points").value;
    calPlans = d.plans;
    $("cal-points").replaceChildren(...calPlans.map((p) => el("option", { value: p.points ?? "" }, p.label)));
    if (calPlans.some((p) => String(p.points ?? "") === keep)) $("cal-points").value = keep;
    showPlan();
  }
  $("cal-points").addEventListener("change", showPlan);
  $("rig").addEventListener("change", loadPlans);

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
        participant_id: pid, rig: $("rig").value, seed: rigSeed(),
        points: $("cal-points").value ? Number($("cal-points").value) : null }) });
      calJob = job_id;
      $("calibrate").disabled = true;
      $("cal-cancel").hidden = false;
      if (!$("calibration").value) onCalibration();  // "Calibrating…", not "No calibration yet"
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
          $("cal-message").textContent = `Calibration #${job.calibration_id} saved` +
            (job.n_errors ? ` with ${job.n_errors} error verdict(s): see below.` : ".");
          flash(`Calibration #${job.calibration_id} saved` + (job.n_errors ? ` with ${job.n_errors} error verdict(s).` : "."), job.n_errors > 0);
          calJob = null;
          await loadParticipants(pid);
          $("calibration").value = job.calibration_id;
          onCalibration();
          break;
        }
        if (job.status === "failed") { $("cal-message").textContent = "Calibration failed."; flash(`Calibration failed: ${job.error}`, true); break; }
        if (job.status === "cancelled") { $("cal-message").textContent = "Calibration cancelled; nothing was saved."; flash("Calibration cancelled; nothing was saved."); break; }
        await new Promise((r) => setTimeout(r, 500));
      }
    } catch (e) { flash(e.message, true); }
    const wasRunning = calJob !== null;
    calJob = null;
    if (wasRunning && !$("calibration").value) onCalibration();  // failed or cancelled: the card says so
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
    await showFigure(url, $("preview-figure"), $("preview-message"), "Rendering…");
  });

  // ---------------------------------------------------------------- sessions
  async function loadSessions() {
    const pid = $("participant").value;
    let sessions = [];  // no participant chosen: no sessions shown
    try { if (pid) sessions = await api(`/api/sessions?participant_id=${encodeURIComponent(pid)}`); }
    catch (e) { if (!offline) flash(e.message, true); return; }
    if (pid !== $("participant").value) return;  // an answer for a participant no longer shown
    // Rows are updated in place and rebuilt only when a status changes, so that the
    // control buttons do not move or vanish under the experimenter's pointer.
    const tbody = $("sessions").querySelector("tbody");
    const existing = new Map(Array.from(tbody.children, (tr) => [tr.dataset.session, tr]));
    if (pendingStop && !sessions.some((s) => s.session_id === pendingStop.session && STOPPABLE.includes(s.status))) {
      pendingStop = null;  // the session ended meanwhile: nothing left to abort
    }
    const rows = sessions.slice().reverse().flatMap((s) => {
      let tr = existing.get(String(s.session_id));
      if (!tr || tr.dataset.status !== s.status) tr = sessionRow(s);
      tr.querySelector(".progress").textContent = `${s.n_answered} / ${s.n_trials}`;
      tr.querySelector(".live").textContent = liveText(s);
      tr.classList.toggle("selected", s.session_id === selectedSession);
      return pendingStop && pendingStop.session === s.session_id ? [tr, pendingStop.row] : [tr];
    });
    if (rows.length !== tbody.children.length || rows.some((tr, i) => tbody.children[i] !== tr)) tbody.replaceChildren(...rows);
    if (!sessions.some((s) => s.session_id === selectedSession)) {
      selectSession(sessions.length ? sessions[sessions.length - 1].session_id : null);
      for (const tr of rows) if (tr.dataset.session) tr.classList.toggle("selected", tr.dataset.session === String(selectedSession));
    }
    loadLive();
  }

  function selectSession(id) {
    if (id === selectedSession) return;
    selectedSession = id;
    liveAsked += 1;  // a reply still on its way is for the session shown before
    $("live-title").textContent = id === null ? "" : `session ${id}`;
    $("live-progress").value = 0;
    $("answers").querySelector("tbody").replaceChildren();
  }

  function trialText(live) {
    // The one numbering of trials: the phase and the trial's number within it, as in
    // the trials file and on the participant page.
    const trial = live && live.trial ? `${live.phase} trial ${live.trial} of ${live.n_in_phase}` : "";
    // A limit over time holds the trial's stimulus until the actuators have cooled.
    return live && live.cooling_s > 0 ? [trial, `cooling: ${Math.ceil(live.cooling_s)} s`].filter(Boolean).join(" · ") : trial;
  }

  // What a session is doing now. A paused session says where it paused, never the state
  // its participant page was in before the pause.
  function liveText(s) {
    if (!s.live) return "—";
    if (s.status === "paused" || s.live.paused) return ["paused", trialText(s.live)].filter(Boolean).join(" at ");
    if (s.live.waiting_for_page) return "waiting for the participant page";
    return [s.live.state, trialText(s.live)].filter(Boolean).join(" · ");
  }

  // What the flash says after a control: what happened, in the words of the status column.
  const DONE = { start: "started", pause: "paused (the participant page shows a break; Resume goes on)", resume: "resumed" };
  const STOPPABLE = ["running", "paused"];

  function sessionRow(s) {
    const link = el("a", { href: s.participant_url, target: "_blank", rel: "noopener" }, "open");
    const copy = el("button", { class: "small", onclick: (ev) => {
      ev.stopPropagation();
      const copied = navigator.clipboard ? navigator.clipboard.writeText(new URL(s.participant_url, location.href).href)
        : Promise.reject(new Error("no clipboard"));
      copied.then(() => flash("Participant link copied."),
        () => flash("The link could not be copied here: right-click 'open' and copy the link address.", true));
    } }, "copy");
    const controls = el("span", { class: "controls" });
    const act = (label, action) => controls.append(el("button", { class: "small", "data-action": action,
      onclick: async (ev) => {
        ev.stopPropagation();
        try { await api(`/api/sessions/${s.session_id}/${action}`, { method: "POST" }); flash(`Session ${s.session_id} ${DONE[action]}.`); }
        catch (e) { flash(e.message, true); }
        selectSession(s.session_id);
        loadSessions();
      } }, label));
    if (s.status === "planned") act("Start", "start");
    if (s.status === "running") act("Pause", "pause");
    if (s.status === "paused") act("Resume", "resume");  // an abort is final: a new session goes on
    if (STOPPABLE.includes(s.status)) {
      // Abort is final (an aborted session never resumes), one button away from Pause: it
      // asks first, in a row of its own under the session's. Not window.confirm(): a modal
      // dialog would swallow the keys, and Esc twice must always reach the emergency stop.
      controls.append(el("button", { class: "small", "data-action": "stop", onclick: (ev) => {
        ev.stopPropagation();
        askStop(s);
      } }, "Abort…"));
    }
    const tr = el("tr", { "data-session": s.session_id, "data-status": s.status },
      el("td", {}, String(s.session_id)), el("td", {}, s.participant_id), el("td", {}, String(s.study)),
      el("td", { class: `status ${s.status}` }, s.status + (s.dry_run ? " · dry run" : "")), el("td", { class: "progress" }), el("td", { class: "live" }),
      el("td", {}, link, " ", copy), el("td", {}, controls));
    // Each cell names its column, for a phone, where the table's rows are blocks.
    const heads = [...$("sessions").tHead.rows[0].cells];
    for (const [i, td] of [...tr.cells].entries()) td.dataset.label = heads[i].textContent;
    tr.addEventListener("click", () => { selectSession(s.session_id); loadSessions(); });
    return tr;
  }

  // {session, row, cancel}: the open question "abort for good?", if any. It has a row of
  // its own, the table's full width, under the session's row: in the narrow control cell
  // it wrapped one word per line and pushed "Keep it" out of the card.
  let pendingStop = null;
  function askStop(s) {
    if (pendingStop) pendingStop.cancel();
    const opener = () => $("sessions").querySelector(`tr[data-session="${s.session_id}"] button[data-action=stop]`);
    const close = () => {
      if (pendingStop && pendingStop.session === s.session_id) pendingStop = null;
      row.remove();
    };
    const cancel = () => { close(); opener()?.focus(); };
    const yes = el("button", { class: "small danger", "data-action": "stop-confirm", onclick: async () => {
      close();
      try { await api(`/api/sessions/${s.session_id}/stop`, { method: "POST" }); flash(`Session ${s.session_id} aborted: it cannot be resumed.`); }
      catch (e) { flash(e.message, true); }
      selectSession(s.session_id);
      loadSessions();
    } }, "Abort for good");
    const no = el("button", { class: "small", "data-action": "stop-cancel", onclick: cancel }, "Keep it");
    const row = el("tr", { class: "confirm-row" }, el("td", { colspan: "8" }, el("div", { class: "confirm-box" },
      el("span", { class: "confirm-stop", role: "alert" },
        `Abort session ${s.session_id} for good? It cannot be resumed; use Pause for a break.`),
      el("span", { class: "controls" }, no, yes))));
    pendingStop = { session: s.session_id, row, cancel };
    $("sessions").querySelector(`tr[data-session="${s.session_id}"]`).after(row);
    no.focus();  // Enter on the focused button keeps the session
  }

  // ---------------------------------------------------------------- protocols
  // A protocol (shipped, or uploaded here) sets the study and design of each of its blocks:
  // with one chosen, Plan session plans its block (default: the participant's next unfinished).
  const MAX_PROTOCOL_UPLOAD = 60000;  // characters: the server's ProtocolIn limit
  let protocols = [];
  async function loadProtocols(select = null) {
    protocols = await api("/api/protocols");
    const keep = select ?? $("protocol").value;
    $("protocol").replaceChildren(el("option", { value: "" }, "none: the study and options below"),
      ...protocols.map((p) => el("option", { value: p.name }, `${p.name}${p.shipped ? "" : " (uploaded)"}`)));
    $("protocol").value = protocols.some((p) => p.name === keep) ? keep : "";
    showBlocks();
  }
  function showBlocks() {
    const p = protocols.find((x) => x.name === $("protocol").value);
    $("block").replaceChildren(el("option", { value: "" }, "next unfinished"),
      ...(p ? p.blocks : []).map((b) => el("option", { value: String(b.index) },
        `${b.index + 1}. ${b.name} · ${b.response} · ${b.n_trials} trials · ${b.levels.join(", ")} ${b.level_unit}`)));
    $("block").disabled = !p;
    for (const id of ["study", "repetitions", "n-training"]) $(id).disabled = Boolean(p);
    $("protocol-message").textContent = p ? (p.description || "") : "";
  }
  $("protocol").addEventListener("change", showBlocks);
  $("protocol-file").addEventListener("change", async () => {
    const file = $("protocol-file").files[0];
    if (!file) return;
    try {
      if (file.size > MAX_PROTOCOL_UPLOAD) throw new Error(`protocol ${file.name}: ${file.size} bytes, more than the ${MAX_PROTOCOL_UPLOAD} this server takes`);
      const p = await api("/api/protocols", { method: "POST", body: JSON.stringify({ text: await file.text(), filename: file.name }) });
      await loadProtocols(p.name);
      flash(`Protocol ${p.name} uploaded: ${p.blocks.length} block(s).`);
    } catch (e) { flash(e.message, true); }
    $("protocol-file").value = "";
  });
  function staircaseText(st) {
    if (st.threshold_db !== null) return `Threshold ${st.threshold_db.toFixed(1)} dB re the level rule (${st.reversals} reversals).`;
    if (st.finished) return `No threshold: the staircase reversed ${st.reversals} times, fewer than it needs; give the block more trials.`;
    return `Staircase: next level ${st.level_db.toFixed(1)} dB, ${st.reversals} reversal(s) so far.`;
  }

  $("new-session").addEventListener("submit", async (ev) => {
    ev.preventDefault();
    const pid = $("participant").value;
    if (!pid) { flash("Add or pick a participant first.", true); return; }
    const cal = $("calibration").value;
    const protocol = $("protocol").value;
    const design = protocol
      ? { protocol, block: $("block").value === "" ? null : Number($("block").value) }
      : { study: Number($("study").value), repetitions: Number($("repetitions").value), n_training: Number($("n-training").value) };
    try {
      const s = await api("/api/sessions", { method: "POST", body: JSON.stringify({
        participant_id: pid, calibration_id: cal ? Number(cal) : null, ...design,
        // With a calibration, the session plays on the forearm it was made on (the server takes
        // its seed): the Seed field is for Calibrate and dry runs only.
        rig: $("rig").value, rig_seed: cal ? null : rigSeed(),
        allow_calibration_errors: Boolean(cal) && $("cal-override").checked }) });
      selectSession(s.session_id);
      const arm = cal && s.config && s.config.rig === "simulated" ? ` on the calibration's simulated forearm (seed ${s.config.rig_seed})` : "";
      flash(`Session ${s.session_id} planned (${s.n_trials} trials)${arm}${cal ? "" : " — no calibration: a dry run, nothing is played"}.`);
      loadSessions();
    } catch (e) { flash(e.message, true); }
  });

  let liveAsked = 0;  // numbers the live panel's requests: only the latest one's reply is shown
  async function loadLive() {
    if (selectedSession === null) return;
    const asked = ++liveAsked;
    let s;
    try { s = await api(`/api/sessions/${selectedSession}`); }
    catch (e) { if (!offline && asked === liveAsked) $("live-title").textContent = `· ${e.message}`; return; }
    if (asked !== liveAsked || s.session_id !== selectedSession) return;  // a slow reply for another session
    const now = s.live ? liveText(s) : "";
    $("live-title").textContent = `session ${s.session_id} · study ${s.study} · ` +
      (now.startsWith(s.status) ? now : [s.status, now].filter(Boolean).join(" · ")) + (s.live && s.live.error ? ` · ${s.live.error}` : "");
    $("live-progress").value = s.n_trials ? s.n_answered / s.n_trials : 0;
    $("live-staircase").hidden = !s.staircase;
    $("live-staircase").textContent = s.staircase ? staircaseText(s.staircase) : "";
    const said = (a) => (s.staircase ? (a.response[0] ? "felt" : "not felt") : a.response.join(" "));
    const rows = s.answers.slice().reverse().map((a) => el("tr", { class: !s.staircase && a.response.includes(a.target) ? "hit" : "" },
      el("td", {}, a.phase), el("td", {}, String(a.trial)), el("td", {}, a.method), el("td", {}, String(a.target)),
      el("td", {}, said(a)), el("td", {}, a.rt_s.toFixed(3)), el("td", {}, a.recorded_at.slice(11, 19))));
    $("answers").querySelector("tbody").replaceChildren(...rows);
  }

  // ---------------------------------------------------------------- export and analysis
  $("analyze").addEventListener("click", async () => {
    try {
      let job = await api("/api/analysis", { method: "POST", body: JSON.stringify({ kind: $("analysis-kind").value }) });
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
  // Every control has its handler from here on: until then a click on "Add" would submit
  // the form to the page itself (a reload that drops what was typed). A test, or a
  // script driving the page, waits for this mark.
  document.body.dataset.ready = "true";
  (async () => {
    try { await loadRigs(); await loadParticipants(); await loadProtocols(); }
    catch (e) { flash(e.message, true); }
    setInterval(loadSessions, 1500);
  })();
})();
