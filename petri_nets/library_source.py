"""The task library written in Python; ``python -m petri_nets.library_source`` writes the PNML
files of petri_nets/library/. The PNML files are what the robots load; this script is how we
author them (one place to read every net side by side).
"""

from __future__ import annotations

import sys
from pathlib import Path

from guidebot.pace import ANSWER_TIMEOUT_S, PATIENCE_S
from petri_nets.builder import (
    NetBuilder,
    guard,
    kill,
    message,
    net_ended,
    next_item,
    publish,
    run,
    timer,
    timer_elapsed,
)
from petri_nets.model import NetDoc
from petri_nets.pnml import write_pnml

__all__ = ["library_nets", "write_library"]

TROUBLE_WAIT_S = 30.0
"""How long a tour waits at a stop that only trouble cuts off (a door jammed, a lift stuck:
"... out of order") for the way to open before it skips the stop (its ``trouble_wait_s``):
a jam of a few seconds costs the visitor a short wait, not the stops behind it."""

EYES = {"open": 0.0, "closed": 60.0, "speed": 180.0}
"""Eyelid positions in degrees and servo speed in degrees per second (the RoboCAN head)."""


def wink_one_eye() -> NetDoc:
    """The paper's Figure 9."""
    b = NetBuilder(
        "wink_one_eye",
        "Open both eyes, wait, close and reopen one eye (Figure 9).",
        params={"eye": "eyelid_right", "hold_s": 0.5, **EYES},
    )
    both_open = {
        "servos": {"eyelid_left": "${open}", "eyelid_right": "${open}"},
        "speed": "${speed}",
    }
    b.place("open_eyes", initial=1, action=publish("move_servos", both_open))
    b.place("left_moving").place("right_moving").place("left_open").place("right_open")
    b.place("wait", action=timer("${hold_s}"))
    b.place(
        "close_eye",
        action=publish("move_servos", {"servos": {"${eye}": "${closed}"}, "speed": "${speed}"}),
    )
    b.place(
        "open_eye",
        action=publish("move_servos", {"servos": {"${eye}": "${open}"}, "speed": "${speed}"}),
    )
    b.place("winked", final=True)
    b.transition("eyes_moving", ["open_eyes"], ["left_moving", "right_moving"])
    b.transition(
        "l_opened",
        ["left_moving"],
        ["left_open"],
        message("servo_in_position", servo="eyelid_left"),
    )
    b.transition(
        "r_opened",
        ["right_moving"],
        ["right_open"],
        message("servo_in_position", servo="eyelid_right"),
    )
    b.transition("both_open", ["left_open", "right_open"], ["wait"])
    b.transition("end_wait", ["wait"], ["close_eye"], timer_elapsed())
    b.transition(
        "eye_closed",
        ["close_eye"],
        ["open_eye"],
        message("servo_in_position", servo="${eye}"),
    )
    b.transition(
        "eye_opened",
        ["open_eye"],
        ["winked"],
        message("servo_in_position", servo="${eye}"),
    )
    return b.build()


def blink() -> NetDoc:
    b = NetBuilder(
        "blink", "Close both eyes, wait until both closed, reopen them.", params=dict(EYES)
    )
    both = {"eyelid_left": "${closed}", "eyelid_right": "${closed}"}
    b.place(
        "close_eyes",
        initial=1,
        action=publish("move_servos", {"servos": both, "speed": "${speed}"}),
    )
    b.place("left_closing").place("right_closing").place("left_closed").place("right_closed")
    b.place(
        "open_eyes",
        action=publish(
            "move_servos",
            {"servos": {"eyelid_left": "${open}", "eyelid_right": "${open}"}, "speed": "${speed}"},
        ),
    )
    b.place("left_opening").place("right_opening").place("left_open").place("right_open")
    b.place("blinked", final=True)
    b.transition("closing", ["close_eyes"], ["left_closing", "right_closing"])
    b.transition(
        "l_closed",
        ["left_closing"],
        ["left_closed"],
        message("servo_in_position", servo="eyelid_left"),
    )
    b.transition(
        "r_closed",
        ["right_closing"],
        ["right_closed"],
        message("servo_in_position", servo="eyelid_right"),
    )
    b.transition("both_closed", ["left_closed", "right_closed"], ["open_eyes"])
    b.transition("opening", ["open_eyes"], ["left_opening", "right_opening"])
    b.transition(
        "l_opened",
        ["left_opening"],
        ["left_open"],
        message("servo_in_position", servo="eyelid_left"),
    )
    b.transition(
        "r_opened",
        ["right_opening"],
        ["right_open"],
        message("servo_in_position", servo="eyelid_right"),
    )
    b.transition("both_open", ["left_open", "right_open"], ["blinked"])
    return b.build()


def head_talk() -> NetDoc:
    b = NetBuilder(
        "head_talk",
        "Open and close the mouth while speaking; endless, killed from "
        "outside when the speech ends.",
        endless=True,
        params={"mouth_open": 20.0, "mouth_closed": 0.0, "period_s": 0.25},
    )
    b.place(
        "mouth_open",
        initial=1,
        action=publish("move_servos", {"servos": {"mouth": "${mouth_open}"}, "speed": 360.0}),
    )
    b.place("hold_open", action=timer("${period_s}"))
    b.place(
        "mouth_close",
        action=publish("move_servos", {"servos": {"mouth": "${mouth_closed}"}, "speed": 360.0}),
    )
    b.place("hold_closed", action=timer("${period_s}"))
    b.transition("opened", ["mouth_open"], ["hold_open"])
    b.transition("open_held", ["hold_open"], ["mouth_close"], timer_elapsed())
    b.transition("closed", ["mouth_close"], ["hold_closed"])
    b.transition("closed_held", ["hold_closed"], ["mouth_open"], timer_elapsed())
    return b.build()


def face_people() -> NetDoc:
    b = NetBuilder(
        "face_people",
        "Turn towards the visitors; gives up after timeout_s.",
        params={"timeout_s": 10.0},
    )
    b.place("turn", initial=1, action=publish("face_people"))
    b.place("patience", initial=1, action=timer("${timeout_s}"))
    b.place("faced", final=True).place("gave_up", final=True)
    b.transition("people_faced", ["turn", "patience"], ["faced"], message("people_faced"))
    b.transition("too_long", ["turn", "patience"], ["gave_up"], timer_elapsed())
    return b.build()


def rest_expression() -> NetDoc:
    b = NetBuilder(
        "rest_expression",
        "Put eyes and mouth in their rest position and wait until every servo is there.",
        params={"eyes": 0.0, "mouth": 0.0},
    )
    b.place(
        "move",
        initial=1,
        action=publish(
            "move_servos",
            {
                "servos": {
                    "eyelid_left": "${eyes}",
                    "eyelid_right": "${eyes}",
                    "mouth": "${mouth}",
                },
                "speed": 180.0,
            },
        ),
    )
    for servo in ("eyelid_left", "eyelid_right", "mouth"):
        b.place(f"{servo}_moving").place(f"{servo}_rest")
    b.place("at_rest", final=True)
    b.transition("moving", ["move"], ["eyelid_left_moving", "eyelid_right_moving", "mouth_moving"])
    for servo in ("eyelid_left", "eyelid_right", "mouth"):
        b.transition(
            f"{servo}_reached",
            [f"{servo}_moving"],
            [f"{servo}_rest"],
            message("servo_in_position", servo=servo),
        )
    b.transition(
        "expression_reached", ["eyelid_left_rest", "eyelid_right_rest", "mouth_rest"], ["at_rest"]
    )
    return b.build()


def explain_point() -> NetDoc:
    """The paper's Figure 10."""
    b = NetBuilder(
        "explain_point",
        "Face the people, then talk with head movements until the "
        "speech ends, then rest the face (Figure 10).",
        params={"lang": "en"},
        required=("text",),
    )
    b.place("address_people", initial=1, action=run("face_people"))
    b.place("head_talk", action=run("head_talk"))
    b.place("synthesize_text", action=publish("say", {"text": "${text}", "lang": "${lang}"}))
    b.place("kill_head_talk", action=kill("head_talk"))
    b.place("rest_expression", action=run("rest_expression"))
    b.place("explained", final=True)
    b.transition(
        "people_faced",
        ["address_people"],
        ["head_talk", "synthesize_text"],
        net_ended("face_people"),
    )
    b.transition("text_spoken", ["synthesize_text"], ["kill_head_talk"], message("speech_ended"))
    b.transition(
        "head_talk_finished",
        ["head_talk", "kill_head_talk"],
        ["rest_expression"],
        net_ended("head_talk"),
    )
    b.transition(
        "expression_reached", ["rest_expression"], ["explained"], net_ended("rest_expression")
    )
    return b.build()


def navigate_to_point() -> NetDoc:
    b = NetBuilder(
        "navigate_to_point",
        "Ask navigation to reach a node (it gets the path from "
        "the Traffic Manager, requests areas, opens doors, rides elevators); fails "
        "when navigation fails.",
        required=("node",),
    )
    b.place("navigate", initial=1, action=publish("navigate_to", {"node": "${node}"}))
    b.place("arrived", final=True).place("failed", final=True, outcome="failed")
    b.transition("goal_reached", ["navigate"], ["arrived"], message("goal_reached", node="${node}"))
    b.transition(
        "navigation_failed", ["navigate"], ["failed"], message("navigation_failed", node="${node}")
    )
    return b.build()


def go_to_poi() -> NetDoc:
    b = NetBuilder(
        "go_to_poi",
        "Take the visitor to one point of interest, show it and explain it.",
        params={"poi": "", "text": "Here we are.", "lang": "en"},
        required=("node",),
    )
    shown = {"poi": "${poi}", "text": "${text}", "lang": "${lang}"}
    b.place("navigate", initial=1, action=run("navigate_to_point", {"node": "${node}"}))
    b.place("show_point", action=publish("show_point", shown))
    b.place("explain_point", action=run("explain_point", {"text": "${text}", "lang": "${lang}"}))
    b.place("arrived", final=True).place("failed", final=True, outcome="failed")
    b.transition("reached", ["navigate"], ["show_point"], net_ended("navigate_to_point", "done"))
    b.transition("not_reached", ["navigate"], ["failed"], net_ended("navigate_to_point"))
    b.transition("shown", ["show_point"], ["explain_point"])
    b.transition("explained", ["explain_point"], ["arrived"], net_ended("explain_point"))
    return b.build()


def battery_charge() -> NetDoc:
    b = NetBuilder(
        "battery_charge",
        "Go to the charging station, dock, wait until charged.",
        params={"station": "station"},
        required=("node",),
    )
    b.place("navigate", initial=1, action=run("navigate_to_point", {"node": "${node}"}))
    b.place("dock", action=publish("dock", {"station": "${station}"}))
    b.place("charging")
    b.place("charged", final=True).place("failed", final=True, outcome="failed")
    b.transition("at_station", ["navigate"], ["dock"], net_ended("navigate_to_point", "done"))
    b.transition("station_not_reached", ["navigate"], ["failed"], net_ended("navigate_to_point"))
    b.transition("docked", ["dock"], ["charging"], message("docked"))
    b.transition("battery_charged", ["charging"], ["charged"], message("charged"))
    return b.build()


def give_tour() -> NetDoc:
    """The paper's Figure 11 with the lesson of section 7.2 (ask before each next point)."""
    b = NetBuilder(
        "give_tour",
        "Visit each point of the tour (navigate, show, explain); before each next "
        "point ask to continue; end on no, on time-out, or when navigation fails (Figure 11). "
        "A point only closed elements lead to (building modes, a jammed door, a stuck lift) "
        "is skipped: point_skipped says which and why, and the tour goes on; one only trouble "
        "cuts off (out of order) is waited for up to trouble_wait_s first.",
        params={
            "question": "Shall we continue the tour?",
            "answer_timeout_s": ANSWER_TIMEOUT_S,  # a slower tour's are longer (guidebot/pace.py)
            "patience_s": PATIENCE_S,
            "trouble_wait_s": TROUBLE_WAIT_S,
            "lang": "en",
        },
        required=("tour", "points"),
    )
    b.place("first_point", initial=1, action=next_item("points", "point"))
    b.place(
        "navigate_to_point",
        action=publish(
            "navigate_to", {"node": "${point.node}", "trouble_wait_s": "${trouble_wait_s}"}
        ),
    )
    b.place(
        "point_skipped",
        action=publish("point_skipped", {"point": "${point}", "reason": "${skip_reason}"}),
    )
    b.place("after_skip", action=next_item("points", "point"))
    b.place(
        "show_point",
        action=publish(
            "show_point",
            {
                "poi": "${point.poi}",
                "text": "${point.text}",
                "point": "${point}",
                "lang": "${lang}",
            },
        ),
    )
    b.place(
        "explain_point", action=run("explain_point", {"text": "${point.text}", "lang": "${lang}"})
    )
    b.place("point_explained", action=publish("point_explained", {"point": "${point}"}))
    b.place("next_point", action=next_item("points", "point"))
    b.place(
        "ask_continue",
        action=publish(
            "ask_continue", {"question": "${question}", "timeout_s": "${answer_timeout_s}"}
        ),
    )
    b.place("answer_wait", action=timer("${patience_s}"))
    b.place("tour_done", final=True)
    b.place("visitor_left", final=True)
    b.place("navigation_failed", final=True, outcome="failed")
    b.transition("has_first", ["first_point"], ["navigate_to_point"], guard("point", "set"))
    b.transition("empty_tour", ["first_point"], ["tour_done"], guard("point", "unset"))
    b.transition(
        "arrived",
        ["navigate_to_point"],
        ["show_point"],
        message("goal_reached", node="${point.node}"),
    )
    b.transition(
        "point_closed",
        ["navigate_to_point"],
        ["point_skipped"],
        message("navigation_failed", {"skip_reason": "reason"}, node="${point.node}", closed=True),
    )
    b.transition(
        "not_arrived",
        ["navigate_to_point"],
        ["navigation_failed"],
        message("navigation_failed", node="${point.node}"),
    )
    b.transition("skipped", ["point_skipped"], ["after_skip"])
    b.transition("skip_to_next", ["after_skip"], ["navigate_to_point"], guard("point", "set"))
    b.transition("skipped_last", ["after_skip"], ["tour_done"], guard("point", "unset"))
    b.transition("shown", ["show_point"], ["explain_point"])
    b.transition("explained", ["explain_point"], ["point_explained"], net_ended("explain_point"))
    b.transition("reported", ["point_explained"], ["next_point"])
    b.transition(
        "more_points", ["next_point"], ["ask_continue", "answer_wait"], guard("point", "set")
    )
    b.transition("last_point_done", ["next_point"], ["tour_done"], guard("point", "unset"))
    b.transition(
        "answer_yes",
        ["ask_continue", "answer_wait"],
        ["navigate_to_point"],
        message("continue_answer", answer="yes"),
    )
    b.transition(
        "answer_no",
        ["ask_continue", "answer_wait"],
        ["visitor_left"],
        message("continue_answer", answer="no"),
    )
    b.transition(
        "answer_timeout",
        ["ask_continue", "answer_wait"],
        ["visitor_left"],
        message("continue_answer", answer="timeout"),
    )
    b.transition("no_answer", ["ask_continue", "answer_wait"], ["visitor_left"], timer_elapsed())
    return b.build()


def waiting() -> NetDoc:
    b = NetBuilder(
        "waiting",
        "Idle behaviour: every pause_s a random gesture (blink or wink); "
        "endless, killed when a main task starts.",
        endless=True,
        params={"pause_s": 8.0, "gestures": ["blink", "wink"]},
    )
    b.place("idle", initial=1, action=timer("${pause_s}"))
    b.place("choose", action=next_item("gestures", "gesture", order="random"))
    b.place("blink", action=run("blink"))
    b.place("wink", action=run("wink_one_eye"))
    b.transition("bored", ["idle"], ["choose"], timer_elapsed())
    b.transition("do_blink", ["choose"], ["blink"], guard("gesture", "equals", "blink"))
    b.transition("do_wink", ["choose"], ["wink"], guard("gesture", "equals", "wink"))
    b.transition("nothing", ["choose"], ["idle"], priority=-1)
    b.transition("blinked", ["blink"], ["idle"], net_ended("blink"))
    b.transition("winked", ["wink"], ["idle"], net_ended("wink_one_eye"))
    return b.build()


def library_nets() -> list[NetDoc]:
    return [
        wink_one_eye(),
        blink(),
        head_talk(),
        face_people(),
        rest_expression(),
        explain_point(),
        navigate_to_point(),
        go_to_poi(),
        battery_charge(),
        give_tour(),
        waiting(),
    ]


def write_library(folder: Path) -> list[Path]:
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for doc in library_nets():
        path = folder / f"{doc.id}.pnml"
        path.write_bytes(write_pnml(doc))
        paths.append(path)
    return paths


if __name__ == "__main__":
    target = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).with_name("library")
    for written in write_library(target):
        print(written)
