
oracle	[2Jcam@1"
seedÿÿÿÿÿÿÿÿÿ"
score_thresholdnan"(
frame_index99999999999999999999999*
rgbUINT8*	"¬*
promptBYTES*Btomato