// Participant page: shows the session state, plays the cue beep, takes answers.
//
// The rule this file is built around: an answer the participant gave is never lost.
// It is written to localStorage (with its answer id) before it is sent, it stays there
// until the server confirms the database commit, and it is re-sent with backoff after a
// lost connection or a reload. The server is idempotent on the answer id, so a re-send
// of an answer that did reach it is harmless.
"use strict";

(() => {
  const body = document.body;
  const sessionId = Number(body.dataset.session);
  const multi = Number(body.dataset.study) === 2;
  const key = new URLSearchParams(location.search).get("key") || "";
  const pendingKey = `vibrofocus.pending.${sessionId}`;
  const $ = (id) => document.getElementById(id);
  const cells = Array.from(document.querySelectorAll(".cell"));
  // A threshold block: each trial asks whether the tap was felt (two buttons, keys Y/1 and N/0).
  const detection = body.dataset.detection === "1";
  const feltButtons = Array.from(document.querySelectorAll(".felt"));
  // A point session: the picture of the arm area (an SVG in mm, y drawn downward).
  const arm = $("arm");
  const area = arm ? ["x0", "x1", "y0", "y1"].reduce((o, k) => ({ ...o, [k]: Number(arm.dataset[k]) }), {}) : null;
  let cursor = null;          // [x, y] mm of the keyboard cursor (layout frame), null until shown

  let seq = -1;               // last state seq seen (long-poll cursor)
  let state = null;           // last state object from the server
  let respondSince = null;    // performance.now() when the grid became answerable: the RT's zero
  let cueSeenFor = null;      // trial whose cue this page showed (so it saw the onset live)
  let restartAskedAt = null;  // state seq at which this page asked for the trial again
  let refused = null;         // {trial_index, text}: the server refused this page's answer
  let selected = new Set();   // Study 2 selection
  let sentFor = null;         // trial index answered on this page (waiting or confirmed)
  let confirmedFor = null;    // trial index whose answer the server confirmed
  let lastBeep = null;        // "trial:seq" of the last cue played, to beep once per cue
  let pausedAt = null;        // {t, trial}: when a break began during an answer window (its clock stops)
  let audio = null;
  let audioReady = false;    // the begin click started audio: cues may play
  let online = true;
  window.vfBeeps = 0;         // count of beeps played (read by the browser tests)

  // ---------------------------------------------------------------- storage
  function loadPending() {
    try { return JSON.parse(localStorage.getItem(pendingKey) || "[]"); } catch { return []; }
  }
  function savePending(list) { localStorage.setItem(pendingKey, JSON.stringify(list)); }
  function dropPending(answerId) { savePending(loadPending().filter((a) => a.answer_id !== answerId)); }
  // Two tabs of one browser share localStorage. Each page sends, and reports on, only its
  // own answers: those it took, and those left stored when it was loaded (a reload or a
  // crash before they were sent). Otherwise one screen would say "Answer taken" for the
  // other's answer, or swallow the refusal of the other's answer.
  const ownIds = new Set(loadPending().map((a) => a.answer_id));
  function ownPending() { return loadPending().filter((a) => ownIds.has(a.answer_id)); }

  function newAnswerId() {
    if (crypto.randomUUID) return crypto.randomUUID().replace(/-/g, "");
    const b = new Uint8Array(16);
    crypto.getRandomValues(b);
    return Array.from(b, (x) => x.toString(16).padStart(2, "0")).join("");
  }

  // ---------------------------------------------------------------- network
  const headers = { "Content-Type": "application/json", "X-Participant-Key": key };
  const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

  // A send that gets no reply within this time is given up and tried again (same answer
  // id, so a request that did reach the server is not stored twice). Tests shorten it.
  const SEND_TIMEOUT_MS = window.vfSendTimeoutMs || 5000;
  let sending = false;
  let stalled = false;        // the last send got no reply in time (the server is slow or unreachable)
  let wakeSender = null;      // ends the sender's back-off at once ("Try again now")
  function backoff(ms) {
    return new Promise((resolve) => {
      const timer = setTimeout(resolve, ms);
      wakeSender = () => { clearTimeout(timer); resolve(); };
    }).finally(() => { wakeSender = null; });
  }
  function setStalled(value) {
    if (stalled === value) return;
    stalled = value;
    $("retry").hidden = !value;
    if (state) render(state);
  }

  async function flushPending() {
    // One sender at a time; retries until every stored answer has a verdict.
    if (sending) return;
    sending = true;
    let delay = 250;
    try {
      for (;;) {
        const list = ownPending();
        if (!list.length) { setStalled(false); return; }
        const answer = list[0];
        const abort = new AbortController();
        const timer = setTimeout(() => abort.abort(), SEND_TIMEOUT_MS);
        let res = null;
        try {
          res = await fetch(`/api/participant/${sessionId}/answer`, {
            method: "POST", headers, body: JSON.stringify(answer), cache: "no-store", signal: abort.signal,
          });
        } catch {
          // No reply: the answer stays stored here and is sent again with the same id.
          if (abort.signal.aborted) setStalled(true); else setOnline(false);
        } finally {
          clearTimeout(timer);
        }
        if (res !== null) setOnline(true);
        if (res !== null && res.ok) {
          dropPending(answer.answer_id);
          setStalled(false);
          confirmedFor = answer.trial_index;
          if (sentFor === answer.trial_index) showTaken();
          delay = 250;
        } else if (res !== null && res.status >= 400 && res.status < 500 && res.status !== 429) {
          // Refused for good (the trial was answered on another screen, the session
          // ended): retrying cannot succeed, so it is dropped and the page says why.
          const detail = await res.json().catch(() => ({}));
          console.warn("answer refused", res.status, detail.detail);
          dropPending(answer.answer_id);
          setStalled(false);
          refused = { trial_index: answer.trial_index, text: refusalText(res.status, detail.detail) };
          if (state) render(state);
        } else {
          if (res !== null) setStalled(true);  // a server error: the same as no reply
          if (state) render(state);  // say that the answer is kept here
          await backoff(delay);
          delay = Math.min(delay * 2, 4000);
        }
      }
    } finally {
      sending = false;
    }
  }

  function refusalText(status, detail) {
    if (status === 409 && detail) return detail;
    if (status === 403) return "This answer was not recorded: this page's link is not valid for the session. Please tell the experimenter.";
    return "This answer was not recorded. Please tell the experimenter.";
  }

  async function askRestart(trialIndex) {
    // This page did not see the stimulus of the trial waiting for an answer (it was
    // reloaded after it): the trial is presented again, so that the reaction time is
    // timed from an onset this page saw.
    try {
      await fetch(`/api/participant/${sessionId}/restart`, {
        method: "POST", headers, cache: "no-store",
        body: JSON.stringify({ session_id: sessionId, trial_index: trialIndex }),
      });
    } catch { /* the next state asks again */ }
  }

  let pollAbort = null;
  function wakePoll() {
    // End the open long-poll so that the next one goes out at once (with ready=1).
    if (pollAbort) pollAbort.abort();
  }

  async function pollLoop() {
    let delay = 250;
    for (;;) {
      try {
        pollAbort = new AbortController();
        let res;
        try {
          res = await fetch(
            `/api/participant/${sessionId}/state?after=${seq}&wait=8&ready=${audioReady ? 1 : 0}`,
            { headers: { "X-Participant-Key": key }, cache: "no-store", signal: pollAbort.signal });
        } catch (e) {
          if (e.name === "AbortError") continue;
          throw e;
        }
        if (res.status === 429) throw new Error("throttled");  // a flood from this computer: retry later
        if (!res.ok) {
          const detail = await res.json().catch(() => ({}));
          setMessage(detail.detail || `The server refused this page (${res.status}).`);
          body.dataset.state = "refused";
          if (res.status === 403 || res.status === 404) return;
          throw new Error(String(res.status));
        }
        setOnline(true);
        delay = 250;
        const next = await res.json();
        if (ownPending().length) flushPending();
        render(next);
      } catch {
        setOnline(false);
        await sleep(delay);
        delay = Math.min(delay * 2, 4000);
      }
    }
  }

  function setOnline(value) {
    if (online === value) return;
    online = value;
    body.classList.toggle("offline", !value);
    if (state) render(state);
  }

  // ---------------------------------------------------------------- audio
  function beep() {
    if (!audio) return;
    // 1 kHz, 150 ms, with 10 ms ramps so the beep does not click.
    const t = audio.currentTime + 0.01;
    const osc = audio.createOscillator();
    const gain = audio.createGain();
    osc.frequency.value = 1000;
    gain.gain.setValueAtTime(0, t);
    gain.gain.linearRampToValueAtTime(0.3, t + 0.01);
    gain.gain.setValueAtTime(0.3, t + 0.14);
    gain.gain.linearRampToValueAtTime(0, t + 0.15);
    osc.connect(gain).connect(audio.destination);
    osc.start(t);
    osc.stop(t + 0.16);
    window.vfBeeps += 1;
  }

  // ---------------------------------------------------------------- rendering
  function setMessage(text) { $("message").textContent = text; }

  function render(next) {
    const previous = state;
    state = next;
    seq = next.seq;
    body.dataset.state = next.state;
    body.dataset.trial = next.trial_index ?? "";
    const newTrial = !previous || previous.trial_index !== next.trial_index;
    if (newTrial) { selected = new Set(); if (arm) { cursor = null; showCursor(); arm.classList.remove("chosen"); } }
    if (next.state === "cue" && audioReady) {
      cueSeenFor = next.trial_index;
      const tag = `${next.trial_index}:${next.seq}`;
      if (tag !== lastBeep) { lastBeep = tag; beep(); }
    }
    if (refused && refused.trial_index !== next.trial_index) refused = null;
    const refusedHere = refused !== null;
    const pendingHere = ownPending().some((a) => a.trial_index === next.trial_index);
    const respond = next.state === "respond";
    // A trial waiting for an answer whose onset this page did not see (it was loaded or
    // reloaded after the stimulus) is asked for again, from "Get ready".
    const restart = !next.simulated && respond && audioReady && cueSeenFor !== next.trial_index && sentFor !== next.trial_index
      && !pendingHere && !refusedHere;
    if (restart && restartAskedAt !== next.seq) {
      restartAskedAt = next.seq;
      askRestart(next.trial_index);
    }

    $("progress").textContent = next.trial ? trialLabel(next) : "";
    body.dataset.phase = next.phase || "";

    // A break (the experimenter paused) stops the trial's clock: the answer window
    // closes, and when it opens again the reaction time goes on from where it stopped.
    const onBreak = Boolean(next.paused) && !["done", "stopped"].includes(next.state);
    if (onBreak && respondSince !== null && pausedAt === null) pausedAt = { t: performance.now(), trial: next.trial_index };
    // A simulated participant's session: the perceptual model answers, this page watches.
    const answerable = !next.simulated && respond && !onBreak && audioReady && !restart && sentFor !== next.trial_index && !pendingHere && !refusedHere;
    const wasAnswerable = body.classList.contains("answerable");
    if (answerable && !wasAnswerable) {
      if (pausedAt !== null && respondSince !== null && pausedAt.trial === next.trial_index) respondSince += performance.now() - pausedAt.t;
      else startAnswering();
    }
    if (!onBreak) pausedAt = null;
    if (!answerable && !onBreak) respondSince = null;
    body.classList.toggle("answerable", answerable);
    body.classList.toggle("on-break", onBreak);
    const waitingForServer = sentFor === next.trial_index && confirmedFor !== next.trial_index;
    $("confirm").hidden = !(multi && answerable);
    for (const c of cells) c.classList.toggle("selected", selected.has(Number(c.dataset.loc)));
    if (!arm) $("hint").textContent = "";

    if (refusedHere && ["respond", "taken"].includes(next.state)) { setMessage(refused.text); return; }
    if (ownPending().length && (!online || stalled)) {
      setMessage(stalled ? "Your answer is saved on this computer. The server has not replied yet — trying again…"
                         : "Answer saved on this computer — reconnecting…");
      return;
    }
    if (!online) { setMessage("Connection lost — reconnecting…"); return; }
    if (next.simulated && !["done", "stopped"].includes(next.state)) {
      setMessage("A simulated participant (the perceptual model) answers this session; nothing to do here.");
      return;
    }
    if (onBreak) { setMessage("Short break. Please wait."); return; }
    switch (next.state) {
      case "waiting": setMessage("Please wait — the experimenter will start the session."); break;
      case "paused": setMessage("Short break. Please wait."); break;
      case "ready":
        // The first main trial after training: say that the training is over.
        setMessage(firstMain(next) ? "Training is over. The main trials begin now. Get ready" : "Get ready");
        break;
      case "cue": setMessage("●"); break;
      case "respond":
        if (restart) setMessage("Get ready");
        else if (waitingForServer) setMessage("Sending…");
        else if (confirmedFor === next.trial_index) showTaken();
        else if (detection) setMessage("Did you feel a tap?");
        else if (arm) setMessage("Where did you feel it? Point at the place.");
        else {
          setMessage(multi ? "Where did you feel it? Choose every location you felt (one or several), then Confirm."
                           : "Where did you feel it most?");
        }
        break;
      case "taken": if (confirmedFor === next.trial_index) showTaken(); else setMessage("Please wait."); break;
      case "done": setMessage("Thank you! The session is complete."); break;
      case "stopped": setMessage("The session has ended."); break;
      case "error": setMessage("Please wait — the experimenter has been notified."); break;
      default: setMessage("Please wait.");
    }
  }

  function firstMain(next) {
    // trial_index > 0: there were training trials before this first main trial.
    return next.phase === "main" && next.trial === 1 && next.trial_index > 0;
  }

  function trialLabel(next) {
    // The numbering of the trials file and the experimenter page: phase, then the
    // trial's number within it.
    return `${next.phase === "training" ? "Training" : "Trial"} ${next.trial} of ${next.n_in_phase}`;
  }

  // The grid becomes answerable: the reaction time starts now, and no cell may carry a
  // hover or focus mark left from the last answer or the Begin click (a response bias).
  let pointerAt = null;       // last known pointer position
  let pointerAnchor = null;   // where the pointer was when the grid became answerable
  function startAnswering() {
    respondSince = performance.now();
    if (arm) { cursor = null; showCursor(); arm.classList.remove("chosen"); }
    if (document.activeElement && document.activeElement.classList.contains("cell")) document.activeElement.blur();
    body.classList.remove("pointer-moved");
    pointerAnchor = pointerAt;
  }
  function trackPointer(ev) {
    pointerAt = [ev.clientX, ev.clientY];
    if (!body.classList.contains("answerable")) return;
    if (pointerAnchor === null) { pointerAnchor = pointerAt; return; }
    // Hover marks show only once the participant moves the pointer on purpose.
    if (Math.hypot(pointerAt[0] - pointerAnchor[0], pointerAt[1] - pointerAnchor[1]) > 4) body.classList.add("pointer-moved");
  }
  document.addEventListener("pointermove", trackPointer);
  document.addEventListener("pointerdown", (ev) => { pointerAt = [ev.clientX, ev.clientY]; });

  function showTaken() {
    body.dataset.taken = "1";
    setMessage("✓ Answer taken");
    body.classList.add("taken");
    setTimeout(() => { body.classList.remove("taken"); delete body.dataset.taken; }, 600);
  }

  // ---------------------------------------------------------------- answering
  function canAnswer() {
    return state && body.classList.contains("answerable") && respondSince !== null;
  }

  function submit(locations) {
    if (!canAnswer()) return;
    if (!locations.length) { $("hint").textContent = "Select at least one location."; return; }
    const rt = (performance.now() - respondSince) / 1000;
    const answer = {
      session_id: sessionId,
      trial_index: state.trial_index,
      response: [...locations].sort((a, b) => a - b),
      rt_s: Math.round(rt * 1e4) / 1e4,
      answer_id: newAnswerId(),
    };
    // Stored before the first send: a crash or reload from here on cannot lose it.
    ownIds.add(answer.answer_id);
    savePending([...loadPending(), answer]);
    sentFor = state.trial_index;
    for (const c of cells) c.classList.toggle("selected", answer.response.includes(Number(c.dataset.loc)));
    body.classList.remove("answerable");
    $("confirm").hidden = true;
    setMessage("Sending…");
    flushPending();
  }

  // An answer (a point or felt / not felt), timed now: stored here before the first send (a
  // crash or reload from here on cannot lose it), then sent.
  function send(fields) {
    const rt = (performance.now() - respondSince) / 1000;
    const answer = {
      session_id: sessionId, trial_index: state.trial_index, ...fields,
      rt_s: Math.round(rt * 1e4) / 1e4, answer_id: newAnswerId(),
    };
    ownIds.add(answer.answer_id);
    savePending([...loadPending(), answer]);
    sentFor = state.trial_index;
    body.classList.remove("answerable");
    setMessage("Sending…");
    flushPending();
    return answer;
  }

  // ---------------------------------------------------------------- detection answers
  function submitFelt(felt) {
    if (!canAnswer()) return;
    send({ felt });
  }
  for (const b of feltButtons) {
    b.addEventListener("click", (ev) => {
      b.blur();  // no focus mark left to bias the next answer
      if (audioReady && ev.detail !== 0) submitFelt(b.dataset.felt === "1");  // detail 0: a key, not the pointer
    });
  }

  // ---------------------------------------------------------------- point answers
  const clamp = (v, lo, hi) => Math.min(Math.max(v, lo), hi);
  function showCursor() {
    const g = $("cursor");
    if (!g) return;
    g.hidden = cursor === null;
    if (cursor !== null) g.setAttribute("transform", `translate(${cursor[0]} ${-cursor[1]})`);
    $("hint").textContent = cursor === null ? "" : `x ${cursor[0].toFixed(0)} mm, y ${cursor[1].toFixed(0)} mm`;
  }
  function submitPoint(point) {
    if (!canAnswer()) return;
    const answer = send({ point_mm: [Math.round(point[0] * 100) / 100, Math.round(point[1] * 100) / 100] });
    cursor = answer.point_mm;
    showCursor();
    arm.classList.add("chosen");
  }
  if (arm) {
    arm.addEventListener("pointerdown", (ev) => {
      if (!audioReady || !canAnswer()) return;
      ev.preventDefault();
      // The screen point in the picture's own units (mm), whatever its scale on this screen.
      const pt = arm.createSVGPoint();
      pt.x = ev.clientX; pt.y = ev.clientY;
      const p = pt.matrixTransform(arm.getScreenCTM().inverse());
      submitPoint([clamp(p.x, area.x0, area.x1), clamp(-p.y, area.y0, area.y1)]);
    });
  }
  function moveCursor(key, big) {
    if (cursor === null) cursor = [(area.x0 + area.x1) / 2, (area.y0 + area.y1) / 2];
    const step = big ? 5 : 1;
    const d = { ArrowLeft: [-step, 0], ArrowRight: [step, 0], ArrowUp: [0, step], ArrowDown: [0, -step] }[key];
    if (d) cursor = [clamp(cursor[0] + d[0], area.x0, area.x1), clamp(cursor[1] + d[1], area.y0, area.y1)];
    showCursor();
  }

  function choose(loc) {
    if (!canAnswer()) return;
    if (!multi) { submit([loc]); return; }
    if (selected.has(loc)) selected.delete(loc); else selected.add(loc);
    for (const c of cells) c.classList.toggle("selected", selected.has(Number(c.dataset.loc)));
    $("hint").textContent = "";
  }

  document.addEventListener("keydown", (ev) => {
    // Enter and Space press a focused button (Begin, Confirm, Try again) as usual. On a
    // cell they would "click" it again (the last one clicked): they never act on a cell.
    // Nothing answers until the participant has begun (after a reload the "Click here
    // to begin" overlay covers the grid).
    const onButton = ev.target instanceof HTMLButtonElement && !ev.target.classList.contains("cell")
      && !ev.target.classList.contains("felt");
    if ((ev.key === "Enter" || ev.key === " ") && onButton) return;
    if (ev.key === "Enter" || ev.key === " ") ev.preventDefault();
    if (!audioReady) return;
    if (detection) {
      const k = ev.key.toLowerCase();
      if (k === "y" || k === "1" || ev.code === "Numpad1") { ev.preventDefault(); submitFelt(true); }
      else if (k === "n" || k === "0" || ev.code === "Numpad0") { ev.preventDefault(); submitFelt(false); }
      return;
    }
    if (arm) {
      // A point session: arrow keys move the cursor (Shift: 5 mm steps), Enter answers at it.
      if (ev.key.startsWith("Arrow")) {
        ev.preventDefault();
        if (canAnswer()) moveCursor(ev.key, ev.shiftKey);
      } else if (ev.key === "Enter" && cursor !== null) {
        submitPoint(cursor);
      } else if (ev.key === "Enter" && canAnswer()) {
        moveCursor("", false);  // the first Enter shows the cursor at the centre; the next answers
      }
      return;
    }
    // Top-row digits and the keypad with NumLock give ev.key "1".."9"; the keypad
    // without NumLock gives navigation keys, so its ev.code is read as well.
    let loc = null;
    if (/^[1-9]$/.test(ev.key)) loc = Number(ev.key);
    else if (/^Numpad[1-9]$/.test(ev.code)) loc = Number(ev.code.slice(6));
    if (loc !== null) { ev.preventDefault(); choose(loc); return; }
    if (ev.key === "Enter" && multi) { ev.preventDefault(); submit([...selected]); return; }
    if ((ev.key === "Backspace" || ev.key === "Escape" || ev.key === "Delete") && multi) {
      selected = new Set();
      for (const c of cells) c.classList.remove("selected");
    }
  });
  for (const c of cells) {
    c.addEventListener("click", (ev) => {
      c.blur();  // no focus left on a cell: no hover or focus mark to bias the next answer
      if (audioReady && ev.detail !== 0) choose(Number(c.dataset.loc));  // detail 0: a key, not the pointer
    });
  }
  $("confirm").addEventListener("click", () => submit([...selected]));
  $("retry").addEventListener("click", () => {
    $("retry").blur();
    if (wakeSender) wakeSender(); else flushPending();
  });

  $("begin").addEventListener("click", async () => {
    // Browsers start audio only after a gesture on the page: this click is it.
    try {
      audio = new (window.AudioContext || window.webkitAudioContext)();
      await audio.resume();
    } catch (e) { console.warn("no audio", e); }
    try { await document.documentElement.requestFullscreen(); } catch { /* headless or refused */ }
    $("begin").blur();  // keys from now on answer; none may press Begin again
    $("overlay").hidden = true;
    audioReady = true;
    if (state) render(state);  // e.g. ask for a trial whose onset came before this page
    wakePoll();
  });

  window.addEventListener("online", () => flushPending());
  flushPending();
  pollLoop();
})();
