#!/usr/bin/env python3
"""Loads the plenoxd viewer page in headless Chromium and takes a screenshot once it shows a map.

Drives Chromium over the DevTools protocol on --remote-debugging-pipe (fd 3: commands in, fd 4:
answers out, each message JSON ended by a NUL byte), so no port is opened. Polls the page's
state, which viewer.js keeps in document.body.dataset (points, faces, mode, cameras, pathPoints,
keyframes, framesDrawn), until the conditions given hold, then captures the viewport as PNG.
With --mesh it then clicks the page's Mesh toggle and waits for the mesh to be drawn first; with
--lod N it first sets the page's mesh detail to N triangles, so the page fetches the map's mesh
as binary glTF at that level of detail and loads it through three.js's GLTFLoader (the state
then says the vertices, triangles and material the loader produced).

Prints the page's last state as one JSON line on stdout. Exit codes: 0 the conditions held and
the screenshot was written; 1 they did not hold before --timeout (the state and any page errors
are printed); 2 Chromium could not be started or talked to. Standard library only; run by
tests/server/viewer_browser_test.cc.
"""

import argparse
import base64
import fcntl
import json
import os
import select
import shutil
import subprocess
import sys
import tempfile
import time


class Browser:
    def __init__(self, chromium, width, height, profile):
        to_chrome_r, to_chrome_w = os.pipe()
        from_chrome_r, from_chrome_w = os.pipe()

        def child_fds():
            # Copied above 4 first: a pipe end may itself be fd 3 or 4 (then dup2 would keep
            # its close-on-exec flag, or overwrite the other end before it is copied).
            high_r = fcntl.fcntl(to_chrome_r, fcntl.F_DUPFD, 10)
            high_w = fcntl.fcntl(from_chrome_w, fcntl.F_DUPFD, 10)
            os.dup2(high_r, 3)
            os.dup2(high_w, 4)

        # WebGL without a GPU: SwiftShader through ANGLE. --no-sandbox: CI runs as root in a
        # container; --disable-dev-shm-usage: containers' /dev/shm is small.
        command = [
            chromium, "--headless=new", "--no-sandbox", "--disable-dev-shm-usage",
            "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--ignore-gpu-blocklist",
            "--remote-debugging-pipe", "--no-first-run", "--no-default-browser-check",
            "--disable-extensions", "--hide-scrollbars", "--mute-audio",
            "--window-size=%d,%d" % (width, height), "--user-data-dir=" + profile,
            "about:blank",
        ]
        self.process = subprocess.Popen(command, preexec_fn=child_fds, close_fds=False,
                                        stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                        stderr=subprocess.DEVNULL)
        os.close(to_chrome_r)
        os.close(from_chrome_w)
        self.out = to_chrome_w
        self.inp = from_chrome_r
        self.buffer = b""
        self.next_id = 0
        self.events = []

    def _read_message(self, deadline):
        while b"\0" not in self.buffer:
            left = deadline - time.monotonic()
            if left <= 0:
                raise TimeoutError("no answer from chromium")
            ready, _, _ = select.select([self.inp], [], [], left)
            if not ready:
                continue
            chunk = os.read(self.inp, 1 << 20)
            if not chunk:
                raise ConnectionError("chromium closed the pipe")
            self.buffer += chunk
        message, self.buffer = self.buffer.split(b"\0", 1)
        return json.loads(message)

    def call(self, method, params=None, session=None, timeout=20.0):
        self.next_id += 1
        message = {"id": self.next_id, "method": method, "params": params or {}}
        if session:
            message["sessionId"] = session
        os.write(self.out, json.dumps(message).encode() + b"\0")
        deadline = time.monotonic() + timeout
        while True:
            answer = self._read_message(deadline)
            if answer.get("id") == self.next_id:
                if "error" in answer:
                    raise RuntimeError("%s: %s" % (method, answer["error"]))
                return answer.get("result", {})
            self.events.append(answer)

    def close(self):
        try:
            self.call("Browser.close", timeout=5)
        except Exception:
            pass
        try:
            self.process.wait(timeout=5)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()


STATE_JS = "JSON.stringify(document.body ? Object.assign({}, document.body.dataset) : {})"


def number(state, key):
    try:
        return int(state.get(key, "0"))
    except ValueError:
        return 0


def page_errors(events):
    errors = []
    for e in events:
        if e.get("method") == "Runtime.exceptionThrown":
            details = e["params"]["exceptionDetails"]
            errors.append(details.get("exception", {}).get("description") or details.get("text"))
        elif e.get("method") == "Runtime.consoleAPICalled" and e["params"]["type"] == "error":
            errors.append(" ".join(str(a.get("value", a.get("description")))
                                   for a in e["params"]["args"]))
    return errors


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--chromium", default="chromium")
    parser.add_argument("--url", required=True)
    parser.add_argument("--out", required=True, help="the screenshot (PNG)")
    parser.add_argument("--width", type=int, default=1100)
    parser.add_argument("--height", type=int, default=620)
    parser.add_argument("--min-points", type=int, default=1)
    parser.add_argument("--min-cameras", type=int, default=0)
    parser.add_argument("--min-path", type=int, default=0)
    parser.add_argument("--path-grows", action="store_true",
                        help="after the rest holds, also wait for the path to grow (the page "
                             "updates without reloading)")
    parser.add_argument("--click-camera", action="store_true",
                        help="then click the first camera of the list and wait for its render")
    parser.add_argument("--mesh", action="store_true",
                        help="then switch the page to Mesh and wait for --min-faces triangles")
    parser.add_argument("--min-faces", type=int, default=1)
    parser.add_argument("--lod", type=int, default=-1,
                        help="with --mesh: the mesh detail (triangles) to choose first; "
                             "-1 keeps the page's")
    parser.add_argument("--timeout", type=float, default=45.0)
    args = parser.parse_args()

    profile = tempfile.mkdtemp(prefix="plx_chromium_")
    browser = None
    try:
        try:
            browser = Browser(args.chromium, args.width, args.height, profile)
            target = browser.call("Target.createTarget", {"url": "about:blank"})["targetId"]
            session = browser.call("Target.attachToTarget",
                                   {"targetId": target, "flatten": True})["sessionId"]
            browser.call("Runtime.enable", session=session)
            browser.call("Page.enable", session=session)
            browser.call("Emulation.setDeviceMetricsOverride",
                         {"width": args.width, "height": args.height, "deviceScaleFactor": 1,
                          "mobile": False}, session=session)
            browser.call("Page.navigate", {"url": args.url}, session=session)
        except (OSError, RuntimeError, TimeoutError, ConnectionError) as e:
            print("cannot drive chromium: %s" % e, file=sys.stderr)
            return 2

        deadline = time.monotonic() + args.timeout
        state, ready_path = {}, None
        while time.monotonic() < deadline:
            result = browser.call("Runtime.evaluate",
                                  {"expression": STATE_JS, "returnByValue": True},
                                  session=session)
            state = json.loads(result.get("result", {}).get("value") or "{}")
            ready = (number(state, "points") >= args.min_points and
                     number(state, "cameras") >= args.min_cameras and
                     number(state, "pathPoints") >= args.min_path and
                     number(state, "framesDrawn") >= 3)
            if ready and args.path_grows and ready_path is None:
                ready_path = number(state, "pathPoints")
            if ready and (not args.path_grows or number(state, "pathPoints") > ready_path):
                renders = number(state, "renders")
                if args.click_camera:
                    browser.call("Runtime.evaluate", {
                        "expression": "document.querySelector('#cameras li[style]').click()"},
                        session=session)
                if args.mesh:
                    if args.lod >= 0:
                        # An option of its own, so any budget can be asked for.
                        browser.call("Runtime.evaluate", {"expression": (
                            "(() => { const s = document.getElementById('mesh-detail');"
                            " s.add(new Option('test', '%d')); s.value = '%d'; })()"
                            % (args.lod, args.lod))}, session=session)
                    browser.call("Runtime.evaluate", {
                        "expression": "document.getElementById('show-mesh').click()"},
                        session=session)
                    while time.monotonic() < deadline and not (
                            state.get("mode") == "mesh" and
                            number(state, "faces") >= args.min_faces and
                            (args.lod < 0 or state.get("lodTriangles") == str(args.lod))):
                        time.sleep(0.1)
                        result = browser.call("Runtime.evaluate",
                                              {"expression": STATE_JS, "returnByValue": True},
                                              session=session)
                        state = json.loads(result.get("result", {}).get("value") or "{}")
                    if number(state, "faces") < args.min_faces:
                        break
                # Two more frames, so the newest trajectory is drawn too (and the render shown).
                drawn = number(state, "framesDrawn")
                while time.monotonic() < deadline and (
                        number(state, "framesDrawn") < drawn + 2 or
                        (args.click_camera and number(state, "renders") <= renders)):
                    time.sleep(0.1)
                    result = browser.call("Runtime.evaluate",
                                          {"expression": STATE_JS, "returnByValue": True},
                                          session=session)
                    state = json.loads(result.get("result", {}).get("value") or "{}")
                shot = browser.call("Page.captureScreenshot", {"format": "png"},
                                    session=session)
                with open(args.out, "wb") as f:
                    f.write(base64.b64decode(shot["data"]))
                print(json.dumps(state))
                return 0
            time.sleep(0.25)
        print(json.dumps(state))
        status = browser.call("Runtime.evaluate", {
            "expression": "(document.getElementById('status') || {}).textContent",
            "returnByValue": True}, session=session)
        print("page status line: %s" % status.get("result", {}).get("value"), file=sys.stderr)
        for error in page_errors(browser.events):
            print("page error: %s" % error, file=sys.stderr)
        print("the page did not reach the state asked for in %.0f s" % args.timeout,
              file=sys.stderr)
        return 1
    finally:
        if browser is not None:
            browser.close()
        shutil.rmtree(profile, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
