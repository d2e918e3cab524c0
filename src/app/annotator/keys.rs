//! Keyboard shortcuts (listed in docs/web-app.md).
use egui::{Key, KeyboardShortcut, Modifiers};

use super::super::canvas::Tool;
use super::Annotator;

const UNDO: KeyboardShortcut = KeyboardShortcut::new(Modifiers::COMMAND, Key::Z);
const REDO: KeyboardShortcut = KeyboardShortcut::new(Modifiers::COMMAND.plus(Modifiers::SHIFT), Key::Z);
const REDO_Y: KeyboardShortcut = KeyboardShortcut::new(Modifiers::COMMAND, Key::Y);

impl Annotator {
    /// Keyboard shortcuts, unless a text field has the keyboard.
    pub(super) fn handle_keys(&mut self, ctx: &egui::Context) {
        if ctx.egui_wants_keyboard_input() {
            return;
        }
        let (undo, redo) = ctx.input_mut(|i| {
            // Check the longer shortcut first: Ctrl+Z would also match Ctrl+Shift+Z.
            let redo = i.consume_shortcut(&REDO) || i.consume_shortcut(&REDO_Y);
            (i.consume_shortcut(&UNDO), redo)
        });
        if redo {
            self.redo();
        } else if undo {
            self.undo();
        }
        let focused = ctx.memory(|m| m.focused());
        let arrows_taken = focused.is_some_and(|id| self.view.arrow_key_widgets.contains(&id));
        let keys = ctx.input(|i| {
            let plain = !i.modifiers.command && !i.modifiers.alt;
            let pressed = |k| plain && i.key_pressed(k);
            let digit = [
                Key::Num1,
                Key::Num2,
                Key::Num3,
                Key::Num4,
                Key::Num5,
                Key::Num6,
                Key::Num7,
                Key::Num8,
                Key::Num9,
            ]
            .iter()
            .position(|&k| pressed(k));
            (
                digit,
                i.num_presses(Key::ArrowRight) as isize - i.num_presses(Key::ArrowLeft) as isize,
                [
                    Key::B,
                    Key::E,
                    Key::OpenBracket,
                    Key::CloseBracket,
                    Key::M,
                    Key::C,
                    Key::S,
                    Key::G,
                    Key::Num0,
                    Key::Space,
                    Key::D,
                    Key::L,
                ]
                .map(pressed),
            )
        });
        let (digit, step, [b, e, smaller, larger, m, c, s, g, fit, space, d, l]) = keys;
        if let Some(i) = digit.filter(|&i| i < self.doc.labels.classes.len()) {
            self.view.select_class(i as u16);
        }
        if !arrows_taken && step != 0 {
            self.view.step(step, self.doc.frame_count());
        }
        if b {
            self.view.tool = Tool::Brush;
        }
        if e {
            self.view.tool = Tool::Eraser;
        }
        if smaller {
            self.view.smaller_brush();
        }
        if larger {
            self.view.larger_brush();
        }
        let layers = &mut self.view.layers;
        layers.mask ^= m;
        layers.confidence ^= c;
        layers.scribbles ^= s;
        layers.ground_truth ^= g && self.doc.scene.has_gt();
        if fit {
            self.view.zoom.reset();
        }
        if space {
            self.training.toggle_pause();
        }
        if d {
            self.download_masks();
        }
        if l {
            self.make_share_link(ctx);
        }
    }
}
