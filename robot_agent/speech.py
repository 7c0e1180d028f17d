"""Speech: say text, publish speech_started / speech_ended around it.

With espeak-ng installed the text is synthesised to a WAV file (never to the speakers of a
server: ``playback=False``) and the robot waits the audio's duration; without it the duration
is simulated from the text length. Either way the wait is robot time, scaled by the clock.
One utterance at a time: a new ``say`` interrupts the current one (ended with interrupted).

``say`` carries the text's language (``lang``, a tag like ``es`` or ``pt-BR``): espeak-ng speaks
it with the voice of that name, else of its base language (``pt``); a language espeak-ng has no
voice for is simulated (timed) and logged. speech_started / speech_ended carry ``lang`` and
``voice`` (None when simulated) so screens and tests know what was heard.
"""

from __future__ import annotations

import asyncio
import logging
import shutil
import subprocess
import tempfile
import wave
from pathlib import Path
from typing import Literal

from guidebot.bus import BusEndpoint
from guidebot.messages import Message
from guidebot.payloads.petri import SpeechEnded, SpeechStarted
from guidebot.service import Service, cancel_and_wait
from robot_agent.clock import Clock

__all__ = ["Speech", "espeak_voices", "simulated_duration", "voice_for"]

log = logging.getLogger(__name__)

WORDS_PER_SECOND = 2.6
ESPEAK_WPM = 175
"""espeak-ng's default rate (words per minute), divided by ``Speech.dwell`` on a slower tour."""
MAX_TEXT = 5000


def espeak_voices(engine: str) -> frozenset[str]:
    """Language tags espeak-ng has voices for (``espeak-ng --voices``), lower case."""
    try:
        out = subprocess.run(
            [engine, "--voices"], capture_output=True, text=True, timeout=10, check=False
        ).stdout
    except (OSError, subprocess.SubprocessError):
        return frozenset()
    return frozenset(line.split()[1].lower() for line in out.splitlines()[1:] if line.split())


def voice_for(lang: str, voices: frozenset[str]) -> str | None:
    """The espeak-ng voice for ``lang``: itself, else its base language when espeak-ng has it
    or any regional voice of it (espeak-ng then takes the one it ranks first for the base:
    British English for ``en``, where the first regional tag by name is Caribbean ``en-029``;
    ``fr-fr`` for ``fr``), else None."""
    tag = lang.lower()
    if tag in voices:
        return tag
    base = tag.split("-")[0]
    if base in voices or any(v.startswith(f"{base}-") for v in voices):
        return base
    return None


def simulated_duration(text: str) -> float:
    """Seconds a speaker takes for ``text``: ~2.6 words per second plus a short pause."""
    return 0.3 + len(text.split()) / WORDS_PER_SECOND


class Speech(Service):
    """The speech module (an endpoint on the on-board bus)."""

    def __init__(
        self,
        endpoint: BusEndpoint,
        clock: Clock,
        *,
        engine: str | None = "auto",
        playback: bool = False,
    ) -> None:
        super().__init__()
        self.ep = endpoint
        self.clock = clock
        self.engine = shutil.which("espeak-ng") if engine == "auto" else engine
        self.playback = playback
        self.speaking: str | None = None
        self.dwell = 1.0
        """A slower tour speaks this many times as long (robot_agent/visitor_needs.py)."""
        self.spoken = 0
        self._voices: frozenset[str] | None = None
        self._task: asyncio.Task[None] | None = None

    async def on_start(self) -> None:
        self.subscribe(self.ep, "say", self._on_say)

    async def on_stop(self) -> None:
        await cancel_and_wait(self._task)

    def _on_say(self, message: Message) -> None:
        text = str(message.payload.get("text") or "")[:MAX_TEXT]
        lang = str(message.payload.get("lang") or "en")
        if self._task is not None and not self._task.done():
            self._task.cancel()
        self._task = asyncio.get_running_loop().create_task(
            self._say(text, lang, message.id), name="speech"
        )

    async def _voice(self, lang: str) -> str | None:
        if not self.engine:
            return None
        if self._voices is None:
            self._voices = await asyncio.to_thread(espeak_voices, self.engine)
        voice = voice_for(lang, self._voices)
        if voice is None:
            log.warning("espeak-ng has no voice for %r: simulating speech", lang)
        return voice

    async def _say(self, text: str, lang: str, request_id: str) -> None:
        self.speaking = text
        voice = await self._voice(lang)
        log.info("saying (%s): %s", voice or f"{lang}, timed", text[:120])
        self.ep.publish(SpeechStarted(text=text, lang=lang, voice=voice), correlation_id=request_id)
        outcome: Literal["done", "interrupted"] = "done"
        try:
            duration = await self._duration(text, voice)
            await self.clock.sleep(duration)
        except asyncio.CancelledError:
            outcome = "interrupted"
            raise
        finally:
            self.speaking = None
            self.spoken += 1
            ended = SpeechEnded(text=text, lang=lang, voice=voice, outcome=outcome)
            self.ep.publish(ended, correlation_id=request_id)

    async def _duration(self, text: str, voice: str | None) -> float:
        dwell = self.dwell
        if not self.engine or voice is None or not text.strip():
            return simulated_duration(text) * dwell if text.strip() else 0.0
        with tempfile.TemporaryDirectory(prefix="guidebot-speech-") as tmp:
            wav = Path(tmp) / "say.wav"
            rate = ["-s", str(round(ESPEAK_WPM / dwell))] if dwell != 1.0 else []
            args = [self.engine, "-v", voice, *rate, "-w", str(wav), "--", text]
            try:
                proc = await asyncio.create_subprocess_exec(
                    *args,
                    stdout=asyncio.subprocess.DEVNULL,
                    stderr=asyncio.subprocess.PIPE,
                )
            except OSError as exc:
                log.warning("espeak-ng failed (%s): simulating speech", exc)
                return simulated_duration(text) * dwell
            try:
                _, err = await proc.communicate()
            except asyncio.CancelledError:
                proc.kill()
                await proc.wait()
                raise
            if proc.returncode != 0 or not wav.exists():
                log.warning("espeak-ng exit %s: %s", proc.returncode, err.decode()[:200])
                return simulated_duration(text) * dwell
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
