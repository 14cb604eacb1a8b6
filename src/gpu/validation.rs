//! Collects validation-layer warnings and errors so tests can fail on any of them.

use std::ffi::{c_void, CStr};
use std::sync::Mutex;

use ash::vk;

#[derive(Default)]
pub(crate) struct ValidationLog {
    messages: Mutex<Vec<String>>,
}

impl ValidationLog {
    pub(crate) fn messages(&self) -> Vec<String> {
        self.messages.lock().unwrap().clone()
    }
}

/// Debug-utils callback: records and prints every warning or error.
pub(crate) unsafe extern "system" fn debug_callback(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    _types: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    user: *mut c_void,
) -> vk::Bool32 {
    // SAFETY: the layer passes valid data for the duration of the call; `user` points to
    // the ValidationLog that Inner keeps alive while the messenger exists.
    let text = unsafe {
        if data.is_null() || (*data).p_message.is_null() {
            "(no message)".to_string()
        } else {
            CStr::from_ptr((*data).p_message)
                .to_string_lossy()
                .into_owned()
        }
    };
    let line = format!("[vulkan {severity:?}] {text}");
    eprintln!("{line}");
    if !user.is_null() {
        let log = unsafe { &*(user as *const ValidationLog) };
        if let Ok(mut m) = log.messages.lock() {
            m.push(line);
        }
    }
    vk::FALSE
}
