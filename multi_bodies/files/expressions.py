"""Expressions of the time ``t`` in data files (the ``.const`` files of articulated bodies), parsed within limits.

An expression is one word of a file, so it is short: a published ``.const``
file writes ``0.5*cos(-100*t)``.  :func:`parse_expression` refuses one longer
than ``MAX_EXPRESSION_CHARACTERS`` or nested deeper than
``MAX_EXPRESSION_DEPTH`` with a one-line UserInputError naming the file and
line, before Python's parser or any recursive walk sees it (a 400 KB
``t+t+...`` once ended in a RecursionError traceback).  What an expression
may contain is checked by its evaluator (``multi_bodies.solver.articulated``).
"""
import ast

from utils import UserInputError

MAX_EXPRESSION_CHARACTERS = 1000
MAX_EXPRESSION_DEPTH = 50


def _depth(tree):
    """Nesting depth of the syntax tree ``tree``, walked without recursion."""
    deepest, stack = 0, [(tree, 1)]
    while stack:
        node, depth = stack.pop()
        deepest = max(deepest, depth)
        if deepest > MAX_EXPRESSION_DEPTH:
            break
        stack.extend((child, depth + 1) for child in ast.iter_child_nodes(node))
    return deepest


def parse_expression(text, where):
    """The syntax tree (``ast.Expression``) of the expression ``text``; UserInputError when it is too long, too
    deeply nested or not an expression.  ``where`` names the file and line."""
    text = text.strip()
    fix = "write an expression of t such as 'cos(-100*t)'"
    if len(text) > MAX_EXPRESSION_CHARACTERS:
        raise UserInputError('%s: an expression of %d characters (at most %d); %s'
                             % (where, len(text), MAX_EXPRESSION_CHARACTERS, fix))
    try:
        tree = ast.parse(text, mode='eval')
    except SyntaxError as err:
        raise UserInputError("%s: cannot read the expression '%s' (%s); %s" % (where, text, err.msg, fix))
    except (RecursionError, MemoryError, ValueError):
        tree = None
    if tree is None or _depth(tree) > MAX_EXPRESSION_DEPTH:
        raise UserInputError("%s: the expression '%s' is nested more than %d levels deep; %s"
                             % (where, text if len(text) < 80 else text[:77] + '...', MAX_EXPRESSION_DEPTH, fix))
    return tree
