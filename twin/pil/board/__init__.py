"""The 3pi's board around the MCU for any program (the C model is ``twin/csrc/pil``): a lap run by an unmodified 3pi
program, ELF or HEX, judged by the physics (:func:`run_board_lap`; :func:`run_program_lap` runs the twin's own
firmware or any other program, :func:`runnable_program` checks one first); the operator who presses its buttons
(:class:`Operator`, or a :class:`Script` read by :func:`load_script`); what the robot showed (:class:`BoardLog`,
:class:`BoardReport`: LCD text over time, buzzer notes, LEDs, the MCU's load)."""

from twin.pil.board import display, lap, operator, report
from twin.pil.board.display import BoardLog, screen_text
from twin.pil.board.lap import check_board, run_board_lap, run_program_lap, runnable_program
from twin.pil.board.operator import Operator, Press, Script, load_script
from twin.pil.board.report import BoardReport

__all__ = ["BoardLog", "BoardReport", "Operator", "Press", "Script", "check_board", "display", "lap", "load_script",
           "operator", "report", "run_board_lap", "run_program_lap", "runnable_program", "screen_text"]
