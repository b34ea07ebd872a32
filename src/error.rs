//! Errors that cross the public surface. Each names the object at fault.

use thiserror::Error;

#[derive(Debug, Error)]
pub enum SceneError {
    #[error("mesh '{mesh}': {what}")]
    Mesh { mesh: String, what: String },
    #[error("material '{material}': {what}")]
    Material { material: String, what: String },
    #[error("light '{light}': {what}")]
    Light { light: String, what: String },
    #[error("texture '{texture}': {what}")]
    Texture { texture: String, what: String },
    #[error("camera: {0}")]
    Camera(String),
    #[error("world: {0}")]
    World(String),
    #[error("not enough memory to build the scene: {0}")]
    Memory(String),
}

#[derive(Debug, Error)]
pub enum RenderError {
    #[error("invalid setting: {0}")]
    Settings(String),
    #[error("image output: {0}")]
    Output(String),
    #[error("not enough memory: {0}")]
    Memory(String),
}
