"""Tests on a real SocketCAN stack (see conftest.py)."""
