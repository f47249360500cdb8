"""``read_input.ReadInput``: the published reader of an input file, as a face over the package's option table.

The published reader keeps every ``option value`` line (a repeated option overrides the earlier one, every
``structure`` line is kept in order, text after ``#`` is a comment) and gives each option of its table a
typed attribute with its default.  This face reads the file the same way, types the options of this package's
table with the table's own conversion (same defaults; the published lubrication drivers' ``Lub_Cut``,
``firm_delta`` and ``repulsion_strength_firm`` are options of the table), and keeps the options this package does
not know as text in ``options`` (the published reader kept them too, and the lubrication drivers read some of
them).

Attributes: every option of the table; ``options`` (dict name -> value text, as written); ``structures``
(list of lists of words: vertex file, clones file, then any further files of the line); ``structures_ID``
(clones file name without folder and ``.clones``); ``input_file``.
"""
import os

from multi_bodies.files import input_options



class ReadInput:
    """The input file ``entries`` (a path) read as the published ``read_input.ReadInput`` reads it."""

    def __init__(self, entries):
        self.input_file = entries
        self.options = {}
        self.structures = []
        self.structures_ID = []
        lines = {}
        try:
            with open(entries, encoding='utf-8') as f:
                text = f.read()
        except (OSError, UnicodeDecodeError) as err:
            raise input_options.UserInputError('%s: cannot be read as a text input file (%s)' % (entries, err))
        for number, raw in enumerate(text.splitlines(), 1):
            line = raw.split('#', 1)[0].strip()
            if not line:
                continue
            words = line.split(None, 1)
            if len(words) < 2:
                raise input_options.UserInputError('%s, line %d: option %s has no value' % (entries, number, words[0]))
            name, value = words[0], words[1].strip()
            if name == 'structure':
                files = value.split()
                self.structures.append(files)
                self.structures_ID.append(os.path.basename(files[1]).rsplit('.clones', 1)[0] if len(files) > 1
                                          else '')
                continue
            self.options[name] = value
            lines[name] = number
        for name, option in input_options.OPTION_TABLE.items():
            value = option.default
            if name in self.options:
                where = '%s, line %d' % (entries, lines[name])
                value = input_options._convert(option.kind, name, self.options[name], where)
            setattr(self, name, value)
