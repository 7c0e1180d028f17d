"""Speech: say text, publish speech_started / speech_ended around it.

With espeak-ng installed the text is synthesised to a WAV file (never to the speakers of a
server: ``playback=False``) and the robot waits the audio's duration; without it the duration
is simulated from the text length. Either way the wait is robot time, scaled by the clock.
One utterance at a time: a new ``say`` interrupts the current one (ended with interrupted).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import shutil
import tempfile
import wave
from collections.abc import Callable
from pathlib import Path

from guidebot.bus import BusEndpoint
from guidebot.messages import Message
from robot_agent.clock import Clock

__all__ = ["Speech", "simulated_duration"]

log = logging.getLogger(__name__)

WORDS_PER_SECOND = 2.6
MAX_TEXT = 5000


def simulated_duration(text: str) -> float:
    """Seconds a speaker takes for ``text``: ~2.6 words per second plus a short pause."""
    return 0.3 + len(text.split()) / WORDS_PER_SECOND


class Speech:
    """The speech module (an endpoint on the on-board bus)."""

    def __init__(
        self,
        endpoint: BusEndpoint,
        clock: Clock,
        *,
        engine: str | None = "auto",
        playback: bool = False,
    ) -> None:
        self.ep = endpoint
        self.clock = clock
        self.engine = shutil.which("espeak-ng") if engine == "auto" else engine
        self.playback = playback
        self.speaking: str | None = None
        self.spoken = 0
        self._task: asyncio.Task[None] | None = None
        self._unsubs: list[Callable[[], None]] = []

    def start(self) -> None:
        self._unsubs = [self.ep.subscribe("say", self._on_say)]

    async def stop(self) -> None:
        for unsub in self._unsubs:
            unsub()
        self._unsubs.clear()
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task

    def _on_say(self, message: Message) -> None:
        text = str(message.payload.get("text") or "")[:MAX_TEXT]
        lang = str(message.payload.get("lang") or "en")
        if self._task is not None and not self._task.done():
            self._task.cancel()
        self._task = asyncio.get_running_loop().create_task(
            self._say(text, lang, message.id), name="speech"
        )

    async def _say(self, text: str, lang: str, request_id: str) -> None:
        self.speaking = text
        log.info("saying: %s", text[:120])
        self.ep.publish("speech_started", {"text": text}, correlation_id=request_id)
        outcome = "done"
        try:
            duration = await self._duration(text, lang)
            await self.clock.sleep(duration)
        except asyncio.CancelledError:
            outcome = "interrupted"
            raise
        finally:
            self.speaking = None
            self.spoken += 1
            self.ep.publish(
                "speech_ended", {"text": text, "outcome": outcome}, correlation_id=request_id
            )

    async def _duration(self, text: str, lang: str) -> float:
        if not self.engine or not text.strip():
            return simulated_duration(text) if text.strip() else 0.0
        with tempfile.TemporaryDirectory(prefix="guidebot-speech-") as tmp:
            wav = Path(tmp) / "say.wav"
            args = [self.engine, "-v", lang, "-w", str(wav), "--", text]
            try:
                proc = await asyncio.create_subprocess_exec(
                    *args,
                    stdout=asyncio.subprocess.DEVNULL,
                    stderr=asyncio.subprocess.PIPE,
                )
            except OSError as exc:
                log.warning("espeak-ng failed (%s): simulating speech", exc)
                return simulated_duration(text)
            try:
                _, err = await proc.communicate()
            except asyncio.CancelledError:
                proc.kill()
                await proc.wait()
                raise
            if proc.returncode != 0 or not wav.exists():
                log.warning("espeak-ng exit %s: %s", proc.returncode, err.decode()[:200])
                return simulated_duration(text)
            with wave.open(str(wav)) as w:
                seconds = w.getnframes() / float(w.getframerate() or 1)
            if self.playback:
                player = shutil.which("aplay")
                if player:
                    play = await asyncio.create_subprocess_exec(
                        player, "-q", str(wav), stderr=asyncio.subprocess.DEVNULL
                    )
                    await play.wait()
                    return 0.0
            return seconds
