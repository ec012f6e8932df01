"""What the long-running operators (Track, Calibrate Actor) share in their modal run: a window-manager timer
that polls the worker, Esc / right-click to cancel, the status in Blender's status bar and redraws."""


def begin_modal(operator, context, interval):
    """Start polling every `interval` seconds; returns the invoke result."""
    wm = context.window_manager
    operator._timer = wm.event_timer_add(interval, window=context.window)
    wm.modal_handler_add(operator)
    return {"RUNNING_MODAL"}


def end_modal(operator, context):
    context.window_manager.event_timer_remove(operator._timer)
    if context.workspace is not None:
        context.workspace.status_text_set(None)


def is_cancel_key(event):
    return event.type in {"ESC", "RIGHTMOUSE"} and event.value == "PRESS"


def show_status(context, text):
    """`text` in the status bar (with the cancel hint) and the sidebar redrawn with the new progress."""
    if context.workspace is not None:
        context.workspace.status_text_set(f"{text}  (Esc to cancel)")
    for area in (context.screen.areas if context.screen else ()):
        if area.type in {"VIEW_3D", "PROPERTIES"}:
            area.tag_redraw()
