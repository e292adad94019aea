"""The local web app for running localization studies (docs/file-formats.md, trials file).

``create_app(db_path, *, token, rig=...)`` builds the FastAPI application with an
experimenter page (participants, calibration, preview, sessions, export) and a
full-screen participant page per session; ``vibrofocus serve`` runs it with uvicorn,
bound to 127.0.0.1.

FastAPI is imported only when this subpackage is, so the rest of vibrofocus works
without the web stack.
"""

from .app import WebState, create_app
from .session_runner import PACES, Pace, SessionRunner

__all__ = ["create_app", "WebState", "SessionRunner", "Pace", "PACES"]
