"""After a lost link the mission's thread asks the operator through the GUI: the question is
shown on the GUI thread, the button chosen goes back to the waiting thread; a STOP meanwhile,
or closing the question, answers "stop"."""

from __future__ import annotations

import threading

from PySide6 import QtWidgets

from fieldapp.mission.incidents import Choice, Incident, IncidentKind
from ui.mission.incident_prompt import IncidentPrompt

INCIDENT = Incident(IncidentKind.LOST_LINK, 4, "station 4: link lost: no reply for 1.0 s")


def _ask_in_thread(prompt: IncidentPrompt) -> tuple[threading.Thread, list[Choice]]:
    answers: list[Choice] = []
    thread = threading.Thread(target=lambda: answers.append(prompt(INCIDENT)), name="mission")
    thread.start()
    return thread, answers


def _button(prompt: IncidentPrompt, choice: Choice) -> QtWidgets.QAbstractButton:
    assert prompt.dialog is not None
    button = prompt.dialog.findChild(QtWidgets.QAbstractButton, f"incident-{choice.value}")
    assert button is not None
    return button


def test_the_operators_choice_goes_back_to_the_mission_thread(qtbot) -> None:
    prompt = IncidentPrompt(stopped=lambda: False)
    thread, answers = _ask_in_thread(prompt)
    qtbot.waitUntil(lambda: prompt.dialog is not None and prompt.dialog.isVisible())
    assert "link lost" in prompt.dialog.informativeText()
    assert {
        c
        for c in Choice
        if prompt.dialog.findChild(QtWidgets.QAbstractButton, f"incident-{c.value}") is not None
    } == set(Choice)
    _button(prompt, Choice.SKIP_STATION).click()
    thread.join(30)
    assert answers == [Choice.SKIP_STATION]
    assert prompt.dialog is None


def test_a_stop_while_asking_answers_stop_and_closes_the_question(qtbot) -> None:
    stop = threading.Event()
    prompt = IncidentPrompt(stopped=stop.is_set)
    thread, answers = _ask_in_thread(prompt)
    qtbot.waitUntil(lambda: prompt.dialog is not None)
    stop.set()
    thread.join(30)
    assert answers == [Choice.STOP]
    qtbot.waitUntil(lambda: prompt.dialog is None)


def test_closing_the_question_without_choosing_stops(qtbot) -> None:
    prompt = IncidentPrompt(stopped=lambda: False)
    thread, answers = _ask_in_thread(prompt)
    qtbot.waitUntil(lambda: prompt.dialog is not None)
    prompt.dialog.reject()
    thread.join(30)
    assert answers == [Choice.STOP]
