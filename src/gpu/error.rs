//! Errors from the GPU plumbing. Each says what was being done and with which adapter or buffer,
//! so a user can tell "no GPU here" from "a kernel is too big for this GPU" from a bug.

#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    /// No adapter at all: no GPU driver and no software fallback.
    #[error("no GPU adapter found (backends tried: {tried}){hint}")]
    NoAdapter { tried: String, hint: &'static str },
    /// The adapter exists but would not give us a device.
    #[error("adapter {adapter} refused to create a device: {source}")]
    RequestDevice {
        adapter: String,
        #[source]
        source: wgpu::RequestDeviceError,
    },
    /// A resource or kernel needs more than this device allows.
    #[error("{what} needs {needed} but this device's {limit} is {allowed}")]
    LimitExceeded {
        what: String,
        limit: &'static str,
        needed: u64,
        allowed: u64,
    },
    /// wgpu rejected something we created (a shader, pipeline, bind group): a bug in our code.
    #[error("GPU validation failed for {what}: {message}")]
    Validation { what: String, message: String },
    /// The device ran out of memory creating or running something.
    #[error("GPU out of memory for {what}")]
    OutOfMemory { what: String },
    /// Mapping a buffer for reading, or waiting for the device, failed (device lost, or a bug).
    #[error("reading {what} back from the GPU failed: {reason}")]
    Readback { what: String, reason: String },
    /// A caller passed arguments that make no sense (sizes of zero, mismatched lengths).
    #[error("{what}: {problem}")]
    InvalidArgument { what: String, problem: String },
}

impl GpuError {
    pub fn invalid_argument(what: impl Into<String>, problem: impl Into<String>) -> Self {
        GpuError::InvalidArgument {
            what: what.into(),
            problem: problem.into(),
        }
    }

    /// Turns an error caught by a wgpu error scope into ours, naming what was being created.
    pub fn from_scope(what: impl Into<String>, error: wgpu::Error) -> Self {
        let what = what.into();
        match error {
            wgpu::Error::OutOfMemory { .. } => GpuError::OutOfMemory { what },
            other => GpuError::Validation {
                what,
                message: with_causes(&other),
            },
        }
    }
}

/// wgpu's own message is often one line with the real reason in its source chain.
fn with_causes(error: &dyn std::error::Error) -> String {
    let mut message = error.to_string();
    let mut cause = error.source();
    while let Some(next) = cause {
        let text = next.to_string();
        if !message.contains(&text) {
            message.push_str(": ");
            message.push_str(&text);
        }
        cause = next.source();
    }
    message
}
