
color*
rgbUINT8*"È*¼
promptBYTES*§B¤tomato, tomato, tomato, tomato, tomato, tomato, tomato, tomato, tomato, tomato, tomato, tomato, tomato, tomato, tomato, tomato, tomato, tomato, tomato, tomato, tomato, tomato, tomato, tomato, tomato, tomato, tomato, tomato, tomato, tomato, ,,,,,,,,,,,,,,,,,,,,,,,,,,,,,,,,,,,,,,,,,, red apple