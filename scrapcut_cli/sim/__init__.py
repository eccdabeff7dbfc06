"""The bundled simulator: procedural scrap pieces with painted reference lines, a D435i model,
a Panda in pybullet, and the recorder. The only code that imports pybullet.
"""
