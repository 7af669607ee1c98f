"""The board's size as the operator enters it (inner corners and square size)."""

from __future__ import annotations

from PySide6 import QtWidgets

from fieldapp.calib.board import Board


class BoardForm(QtWidgets.QWidget):
    def __init__(self, board: Board, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.cols = _spin(3, 30, board.cols)
        self.rows = _spin(3, 30, board.rows)
        self.square_mm = QtWidgets.QDoubleSpinBox()
        self.square_mm.setRange(5.0, 500.0)
        self.square_mm.setDecimals(1)
        self.square_mm.setValue(board.square_mm)
        self.square_mm.setSuffix(" mm")
        form = QtWidgets.QFormLayout(self)
        form.addRow("inner corners across", self.cols)
        form.addRow("inner corners down", self.rows)
        form.addRow("square size", self.square_mm)

    def board(self) -> Board:
        return Board(self.cols.value(), self.rows.value(), self.square_mm.value())


def _spin(low: int, high: int, value: int) -> QtWidgets.QSpinBox:
    spin = QtWidgets.QSpinBox()
    spin.setRange(low, high)
    spin.setValue(value)
    return spin
