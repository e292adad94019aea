"""Attacks a reviewer would try, in a real chromium against a real server.

A page served by another program on this computer (another port of 127.0.0.1 is the
same *site* to a browser, so a SameSite cookie alone does not stop it), DNS rebinding
(a foreign host name), framing, the token in a URL, and malformed secrets and ids.
"""

from __future__ import annotations

import http.server
import socket
import threading
import time

import httpx
import pytest

from .conftest import free_port, login
from .test_api import snapshot, wait_state

pytestmark = pytest.mark.browser


class OtherLocalSite:
    """A page served by 'another local program': a plain HTTP server on another port."""

    def __init__(self, html: str) -> None:
        body = html.encode()

        class Handler(http.server.BaseHTTPRequestHandler):
            def do_GET(self):  # noqa: N802 - http.server's name
                self.send_response(200)
                self.send_header("Content-Type", "text/html; charset=utf-8")
                self.send_header("Content-Length", str(len(body)))
                self.end_headers()
                self.wfile.write(body)

            def log_message(self, *args):
                pass

        self.httpd = http.server.ThreadingHTTPServer(("127.0.0.1", free_port()), Handler)
        self.url = f"http://127.0.0.1:{self.httpd.server_address[1]}/"
        threading.Thread(target=self.httpd.serve_forever, daemon=True).start()

    def close(self) -> None:
        self.httpd.shutdown()
        self.httpd.server_close()


def test_a_page_of_another_local_program_can_neither_act_nor_frame(server, chromium):
    s = server.plan("P30", 1)
    sid = s["session_id"]
    key = s["participant_url"].split("key=")[1]
    assert server.api("POST", f"/api/sessions/{sid}/start").status_code == 200
    wait_state(server, sid, key, "respond")
    target = server.base_url
    evil = OtherLocalSite(f"""<!doctype html><html><body>
<iframe id="framed" src="{target}/" width="800" height="600"></iframe>
<iframe name="sink"></iframe>
<form id="stop" method="post" action="{target}/api/sessions/{sid}/stop" target="sink"></form>
<script>
  const opts = {{method: "POST", credentials: "include", mode: "no-cors"}};
  Promise.allSettled([
    fetch("{target}/api/sessions/{sid}/pause", opts),
    fetch("{target}/api/analysis", {{...opts, body: "{{}}", headers: {{"Content-Type": "text/plain"}}}}),
    fetch("{target}/api/participants", {{...opts, body: "participant_id=X", headers: {{"Content-Type": "application/x-www-form-urlencoded"}}}}),
  ]).then(() => {{ document.getElementById("stop").submit(); window.attackDone = true; }});
</script></body></html>""")
    context = chromium.new_context()
    context.set_default_timeout(15_000)
    try:
        exp = context.new_page()
        login(exp, server)  # the experimenter is logged in in this browser
        before = snapshot(server.db)
        attack = context.new_page()
        attack.goto(evil.url)
        attack.wait_for_function("window.attackDone === true")
        attack.wait_for_timeout(1000)
        # Nothing changed: the session still runs, no analysis, no participant.
        assert server.rows("SELECT status FROM sessions WHERE session_id = ?", sid) == [("running",)]
        after = snapshot(server.db)
        assert after["participants"] == before["participants"]
        assert [e for e in after["events"] if e[2] in ("pause", "abort")] == []
        assert not (server.db.parent / "studies-files" / "reports").exists()
        # The experimenter page did not load inside the other site's frame.
        framed = attack.query_selector("#framed").content_frame()
        assert "participant-card" not in _content(framed)
    finally:
        context.close()
        evil.close()


def _content(frame) -> str:
    try:
        return frame.content()
    except Exception:  # noqa: BLE001 - a blocked frame has no document to read
        return ""


def test_login_link_works_once_and_the_token_never_goes_in_a_url(server, chromium):
    link = server.login_link()
    assert server.token not in link
    context = chromium.new_context()
    context.set_default_timeout(15_000)
    try:
        page = context.new_page()
        page.goto(link)
        page.wait_for_selector("#participant-card")
        assert page.url == server.base_url + "/"
        (cookie,) = [c for c in context.cookies() if c["name"] == "vf_token"]
        assert cookie["httpOnly"] and cookie["sameSite"] == "Strict"
        assert server.token not in cookie["value"], "the cookie holds a derived value, not the token"
        assert page.evaluate("document.cookie") == "", "no script can read the login cookie"
        # The page's own requests work with the cookie (a POST with its Origin).
        page.fill("#new-participant-id", "P31")
        page.click("#new-participant button")
        page.wait_for_function("document.getElementById('participant').value === 'P31'")
    finally:
        context.close()
    context = chromium.new_context()
    try:
        page = context.new_page()
        page.goto(link)
        assert "used already" in page.inner_text("body")
        assert not page.query_selector("#participant-card")
        # The token in the address bar no longer logs in, and the login form posts it.
        page.goto(f"{server.base_url}/?token={server.token}")
        assert not page.query_selector("#participant-card")
        assert page.get_attribute("main.login form", "method") == "post"
        assert [c for c in context.cookies() if c["name"] == "vf_token"] == []
    finally:
        context.close()


def test_security_headers_on_pages_and_api(server):
    s = server.plan("P32", 2)
    for path, headers in (("/", {}), (s["participant_url"], {}), ("/api/rigs", server.headers), ("/static/participant.js", {})):
        r = httpx.get(server.base_url + path, headers=headers)
        assert r.status_code == (401 if path == "/" else 200), path  # "/": the login page
        assert "frame-ancestors 'none'" in r.headers["content-security-policy"], path
        assert r.headers["x-frame-options"] == "DENY"
        assert r.headers["x-content-type-options"] == "nosniff"


def test_foreign_host_names_and_origins_are_refused(server):
    port = server.port
    # DNS rebinding: a foreign name that resolves to 127.0.0.1 sends that name as Host.
    r = httpx.get(server.base_url + "/api/rigs", headers={**server.headers, "Host": f"attacker.example:{port}"})
    assert r.status_code == 400 and "127.0.0.1" in r.json()["detail"]
    r = httpx.get(server.base_url + "/", headers={"Host": f"attacker.example:{port}"})
    assert r.status_code == 400
    assert httpx.get(f"http://localhost:{port}/api/rigs", headers=server.headers).status_code == 200
    # A state-changing request from another origin (or its Referer) is refused, even with the token.
    for extra in ({"Origin": "http://127.0.0.1:1"}, {"Referer": "http://127.0.0.1:1/page"}, {"Origin": "null"}):
        r = server.api("POST", "/api/participants", json={"participant_id": "P33"}, headers=extra)
        assert r.status_code == 403, extra
        assert "not part of this study server" in r.json()["detail"]
    assert server.api("GET", "/api/participants").json() == []
    r = server.api("POST", "/api/participants", json={"participant_id": "P33"},
                   headers={"Origin": server.base_url})
    assert r.status_code == 201


def test_malformed_secrets_and_huge_ids_get_4xx(server):
    s = server.plan("P34", 1)
    sid = s["session_id"]
    base = server.base_url
    bad_token = {"X-Vibrofocus-Token": "jeton-é-ü-ß-не-тот".encode()}
    r = httpx.get(base + "/api/participants", headers=bad_token)
    assert r.status_code == 401 and "not logged in" in r.json()["detail"]
    r = httpx.get(base + "/api/participants", headers={"Cookie": "vf_token=é".encode()})
    assert r.status_code == 401
    r = httpx.get(f"{base}/api/participant/{sid}/state", headers={"X-Participant-Key": "clé-é".encode()})
    assert r.status_code == 403
    r = httpx.get(f"{base}/participant/{sid}", params={"key": "clé-é"})
    assert r.status_code == 403
    huge = 10**30
    for method, path in (("GET", f"/api/sessions/{huge}"), ("POST", f"/api/sessions/{huge}/start"),
                         ("GET", f"/api/calibrations/{huge}/figure.png"),
                         ("GET", f"/api/preview.png?calibration_id={huge}&method=inverse&location=5"),
                         ("GET", f"/api/sessions/{2**63}")):
        r = server.api(method, path)
        assert 400 <= r.status_code < 500, (path, r.status_code, r.text)
    for path in (f"/participant/{huge}", f"/api/participant/{huge}/state"):
        r = httpx.get(base + path, params={"key": "x"}, headers={"X-Participant-Key": "x"})
        assert 400 <= r.status_code < 500, (path, r.status_code)
    key = s["participant_url"].split("key=")[1]
    r = httpx.post(f"{base}/api/participant/{sid}/answer", headers={"X-Participant-Key": key},
                   json={"session_id": huge, "trial_index": huge, "response": [5], "rt_s": 1.0, "answer_id": "abcdefgh"})
    assert r.status_code == 422


def _rss_kib(pid: int) -> int:
    with open(f"/proc/{pid}/status") as fh:
        return next(int(line.split()[1]) for line in fh if line.startswith("VmRSS:"))


def _raw_post(server, path: str, headers: dict[str, str], chunks, *, chunked: bool) -> int:
    """POST with a raw socket, sending ``chunks`` until the server answers; its status."""
    with socket.create_connection(("127.0.0.1", server.port), timeout=10) as sock:
        head = [f"POST {path} HTTP/1.1", f"Host: 127.0.0.1:{server.port}", "Content-Type: application/json"]
        head += [f"{k}: {v}" for k, v in headers.items()]
        head.append("Transfer-Encoding: chunked" if chunked else f"Content-Length: {sum(len(c) for c in chunks)}")
        sock.sendall(("\r\n".join(head) + "\r\n\r\n").encode())
        try:
            for c in chunks:
                sock.sendall(b"%x\r\n%s\r\n" % (len(c), c) if chunked else c)
            if chunked:
                sock.sendall(b"0\r\n\r\n")
        except OSError:
            pass  # the server answered and closed before reading it all: that is the point
        reply = sock.recv(4096)
    return int(reply.split(b" ", 2)[1])


def test_huge_bodies_are_refused_before_they_are_read(server):
    s = server.plan("P35", 1)
    sid = s["session_id"]
    key = s["participant_url"].split("key=")[1]
    pid = server.proc.pid
    before = _rss_kib(pid)
    chunk = b"[" + b"1," * (512 * 1024)  # about 1 MB of a JSON list
    t0 = time.monotonic()
    # Declared too large: refused at once, with or without credentials.
    assert _raw_post(server, "/api/participants", server.headers, [chunk] * 100, chunked=False) == 413
    assert _raw_post(server, "/api/participants", {}, [chunk] * 100, chunked=False) == 401
    # Sent without a length: refused as soon as it passes the limit.
    assert _raw_post(server, f"/api/participant/{sid}/answer", {"X-Participant-Key": key}, [chunk] * 100, chunked=True) == 413
    assert time.monotonic() - t0 < 10
    grown_mib = (_rss_kib(pid) - before) / 1024
    assert grown_mib < 20, f"the server grew by {grown_mib:.0f} MiB for refused uploads"
    assert server.api("GET", "/api/rigs").status_code == 200, "the server still answers"


def test_database_and_exports_are_private_and_one_analysis_at_a_time(server):
    s = server.plan("P36", 1)
    assert server.api("GET", "/api/export/trials.csv").status_code == 200
    files = server.db.parent / "studies-files"
    # The export is served from memory: its private working folder is gone once it is sent.
    assert not list((files / "exports").iterdir())
    modes = {p.name: p.stat().st_mode & 0o777 for p in (server.db, files, files / "exports")}
    wal = server.db.with_name(server.db.name + "-wal")
    if wal.exists():
        modes[wal.name] = wal.stat().st_mode & 0o777
    assert all(m & 0o077 == 0 for m in modes.values()), {k: oct(m) for k, m in modes.items()}
    # Answer one trial so that there is something to analyse, then ask twice at once.
    sid = s["session_id"]
    key = s["participant_url"].split("key=")[1]
    assert server.api("POST", f"/api/sessions/{sid}/start").status_code == 200
    st = wait_state(server, sid, key, "respond")
    r = httpx.post(f"{server.base_url}/api/participant/{sid}/answer", headers={"X-Participant-Key": key},
                   json={"session_id": sid, "trial_index": st["trial_index"], "response": [5], "rt_s": 0.5, "answer_id": "cap-test-1"})
    assert r.status_code == 200, r.text
    replies = [server.api("POST", "/api/analysis", json={}) for _ in range(4)]
    assert [r.status_code for r in replies].count(202) == 1, [r.text for r in replies]
    assert all(r.status_code == 409 and "already running" in r.json()["detail"] for r in replies[1:])
    assert len(list((files / "reports").iterdir())) == 1


@pytest.mark.parametrize("attacker_host", ["localhost", "127.0.0.1"])  # another site; another port of this one
def test_a_web_page_of_junk_login_images_does_not_lock_the_experimenter_out(server, chromium, attacker_host):
    # Issue 38, item 11: <img src="http://127.0.0.1:PORT/login/junk"> on any page the lab PC visits.
    s = server.plan("P31", 1)
    sid, key = s["session_id"], s["participant_url"].split("key=")[1]
    target = server.base_url
    images = "".join(f'<img src="{target}/login/junk-{i}"><img src="{target}/participant/{sid}?key=junk{i}">'
                     for i in range(30))
    evil = OtherLocalSite(f"""<!doctype html><html><body>{images}
<script>window.addEventListener("load", () => {{ window.attackDone = true; }});</script></body></html>""")
    evil.url = evil.url.replace("127.0.0.1", attacker_host)
    context = chromium.new_context()
    context.set_default_timeout(15_000)
    try:
        attack = context.new_page()
        seen = []
        attack.on("request", lambda req: seen.append(req.url) if req.url.startswith(target) else None)
        attack.goto(evil.url)
        attack.wait_for_function("window.attackDone === true")
        assert len(seen) == 60, f"the page sent {len(seen)} of its 60 requests"
        exp = context.new_page()
        login(exp, server)  # the login form with the right token gets in
        participant = context.new_page()
        participant.goto(target + s["participant_url"])
        r = participant.evaluate(f"""fetch("/api/participant/{sid}/state", {{headers: {{"X-Participant-Key": "{key}"}}}})
                                     .then(r => r.status)""")
        assert r == 200
    finally:
        context.close()
        evil.close()
