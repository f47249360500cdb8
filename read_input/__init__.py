"""Published import paths of the input readers (``from read_input import read_input``, ...), for drivers and
override files written for the published package (its lubrication examples' ``main_*.py``, for one).

Thin faces over ``multi_bodies.files``; the package itself never imports them.
"""
