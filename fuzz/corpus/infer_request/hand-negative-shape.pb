
color*
rgbUINT8þÿÿÿÿÿÿÿÿ*
promptBYTES*Btomato