"""A scene whose film is not square: the shipped Cornell box at 32x24, without its ``res``
parameter (so a resolution override edits the film, ``scene_xml.edited_xml``)."""
import os

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CORNELL = os.path.join(ROOT, "scenes", "cornell_box.xml")


def wide_cornell(folder, width: int = 32, height: int = 24) -> str:
    """Write the Cornell box with a width x height film and no ``res`` parameter into ``folder``;
    its path."""
    with open(CORNELL) as f:
        text = f.read()
    text = text.replace('<default name="res" value="64"/>', "")
    text = text.replace('name="width" value="$res"', f'name="width" value="{width}"')
    text = text.replace('name="height" value="$res"', f'name="height" value="{height}"')
    path = os.path.join(folder, "wide.xml")
    with open(path, "w") as f:
        f.write(text)
    return path
