"""Simulated visitors for ``guidebot demo --scenario busy``: seeded, so a demo can be replayed.

Every few seconds a visitor presses a building button (the simulator's control API), asks for a
tour at the visitor panel (``POST /api/tasks`` with the panel's token, as the page does), or
answers a robot's "continue the tour?" on its touch screen (mostly yes). They stop asking for
tours while as many tasks wait as there are robots, so the queue stays short.
"""

from __future__ import annotations

import logging
import random
from dataclasses import dataclass, field

import httpx

__all__ = ["Visitors"]

log = logging.getLogger(__name__)

YES_SHARE = 0.85
"""Share of "continue?" answers that are yes (the paper: 35% walked away mid-tour, mostly by
leaving, which the robot's time-out covers)."""


@dataclass
class Visitors:
    server: str
    panel_token: str
    admin_token: str
    building: str
    """The building simulator's control URL."""
    buttons: list[str]
    tours: list[str]
    screens: list[str]
    seed: int = 1
    every_s: float = 8.0
    """Mean time between two visitor actions (wall seconds)."""
    rng: random.Random = field(init=False)
    actions: dict[str, int] = field(init=False)

    def __post_init__(self) -> None:
        self.rng = random.Random(self.seed)
        self.actions = {"press": 0, "tour": 0, "answer": 0}
        self.due = 0.0
        self._answer_at: dict[str, tuple[tuple[str, str], float]] = {}

    def tick(self, http: httpx.Client, now: float) -> list[str]:
        """Called about twice a second: answer open questions, and act when an action is due."""
        done = self._answer(http, now)
        if now >= self.due:
            if self.due:  # not at the very first tick: let the fleet settle first
                action = self._act(http)
                if action:
                    done.append(action)
            self.due = now + self.rng.expovariate(1.0 / self.every_s)
        return done

    def _act(self, http: httpx.Client) -> str | None:
        try:
            if self.rng.random() < 0.4 and self.buttons:
                button = self.rng.choice(self.buttons)
                http.post(f"{self.building}/buttons/{button}/press", json={"ms": 600})
                self.actions["press"] += 1
                return f"a visitor pressed {button}"
            if self.tours and not self._queue_full(http):
                tour = self.rng.choice(self.tours)
                reply = http.post(
                    f"{self.server}/api/tasks",
                    json={"kind": "tour", "params": {"tour": tour}},
                    headers={"Authorization": f"Bearer {self.panel_token}"},
                )
                if reply.status_code < 300:
                    self.actions["tour"] += 1
                    return f"a visitor asked for the {tour} tour at the visitor panel"
                log.info("visitor panel: %s %s", reply.status_code, reply.text[:200])
        except httpx.HTTPError as exc:
            log.info("visitor: %s", exc)
        return None

    def _queue_full(self, http: httpx.Client) -> bool:
        reply = http.get(
            f"{self.server}/api/tasks",
            params={"state": "queued"},
            headers={"Authorization": f"Bearer {self.admin_token}"},
        )
        return reply.status_code != 200 or reply.json().get("total", 0) >= len(self.screens)

    def _answer(self, http: httpx.Client, now: float) -> list[str]:
        """A visitor reads each open "continue the tour?" and answers after 1 to 4 s."""
        done = []
        for screen in self.screens:
            try:
                question = http.get(f"{screen}/api/screen").json().get("question")
            except (httpx.HTTPError, ValueError):
                continue  # that robot is restarting
            if not question:
                self._answer_at.pop(screen, None)
                continue
            key = (str(question.get("id")), screen)
            at = self._answer_at.setdefault(screen, (key, now + self.rng.uniform(1.0, 4.0)))
            if at[0] != key:
                at = self._answer_at[screen] = (key, now + self.rng.uniform(1.0, 4.0))
            if now < at[1]:
                continue
            answer = "yes" if self.rng.random() < YES_SHARE else "no"
            try:
                http.post(f"{screen}/api/answer", json={"answer": answer})
            except httpx.HTTPError:
                continue
            del self._answer_at[screen]
            self.actions["answer"] += 1
            done.append(f"a visitor answered {answer} to 'continue the tour?' at {screen}")
        return done
