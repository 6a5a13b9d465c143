
color*
rgbUINT8*
promptBYTES:È :
ÿÿÿÿtomato