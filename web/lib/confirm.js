// An accessible confirmation for actions that cannot be undone (cancel a task, roll back the
// site): a modal <dialog> named by its title, focus on the safe choice, Escape keeps things
// as they are. Resolves true only when the person chose the action.

/**
 * @param {{title: string, text: string, confirm: string, keep: string}} words
 * @returns {Promise<boolean>}
 */
export function confirmAction({ title, text, confirm, keep }) {
  return new Promise((resolve) => {
    const dialog = document.createElement("dialog");
    dialog.className = "confirm";
    const id = `confirm-${Math.random().toString(36).slice(2)}`;
    dialog.setAttribute("aria-labelledby", `${id}-title`);
    dialog.setAttribute("aria-describedby", `${id}-text`);
    const heading = document.createElement("h3");
    heading.id = `${id}-title`;
    heading.textContent = title;
    const para = document.createElement("p");
    para.id = `${id}-text`;
    para.textContent = text;
    const actions = document.createElement("div");
    actions.className = "actions";
    const yes = document.createElement("button");
    yes.type = "button";
    yes.className = "danger";
    yes.textContent = confirm;
    const no = document.createElement("button");
    no.type = "button";
    no.className = "secondary";
    no.textContent = keep;
    actions.append(yes, no);
    dialog.append(heading, para, actions);
    let answer = false;
    yes.addEventListener("click", () => {
      answer = true;
      dialog.close();
    });
    no.addEventListener("click", () => dialog.close());
    dialog.addEventListener("close", () => {
      dialog.remove();
      resolve(answer);
    });
    document.body.append(dialog);
    dialog.showModal();
    no.focus();
  });
}
