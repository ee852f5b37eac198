// The pages' one connection to the server: JSON messages, and the binary images that follow
// the JSON message announcing them.
"use strict";

function openSocket(path, onMessage, onStatus) {
  const scheme = location.protocol === "https:" ? "wss:" : "ws:";
  const socket = new WebSocket(`${scheme}//${location.host}${path}`);
  socket.binaryType = "blob";
  let announced = null;
  socket.addEventListener("message", (event) => {
    if (typeof event.data === "string") {
      const message = JSON.parse(event.data);
      if (message.type === "pass" || message.type === "rendered") {
        announced = message;
      } else {
        onMessage(message, null);
      }
    } else if (announced !== null) {
      const header = announced;
      announced = null;
      onMessage(header, event.data);
    }
  });
  socket.addEventListener("close", () => onStatus("disconnected from the server", true));
  return {
    send(message) {
      if (socket.readyState === WebSocket.OPEN) socket.send(JSON.stringify(message));
    },
    ready: new Promise((resolve) => socket.addEventListener("open", resolve)),
  };
}

function setStatus(element, text, isError) {
  element.textContent = text;
  element.classList.toggle("error", Boolean(isError));
}

function download(blob, name) {
  const link = document.createElement("a");
  link.href = URL.createObjectURL(blob);
  link.download = name;
  document.body.appendChild(link);
  link.click();
  link.remove();
  setTimeout(() => URL.revokeObjectURL(link.href), 10000);
}
