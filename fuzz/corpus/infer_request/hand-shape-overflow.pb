
color*
rgbUINT8€€€€€€€€@*
promptBYTES*Btomato