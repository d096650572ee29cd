/* The control client exercised from C: the Rust test (capi/tests/control.rs) compiles this file
 * against libfrictionless.so and libfrictionless.a, runs it against a live frictiond (or none), and
 * checks what it prints against the daemon's configuration and rules.
 *
 * usage: control PREFIX ROOT_PATH TIMEOUT_MS OP...
 *   OP: get:JOINT or set:JOINT:KEY:VALUE, sent in order through one handle.
 * Prints one line per OP:
 *   STATUS CONTROL_STATUS JOINT_INDEX KFC MAX_OUTPUT_FRICTION MAX_CURR COMPENSATION OOD MODEL KIND
 *   N_MODELS MODELS SET_SINCE_KFC SET_SINCE_COMPENSATION SET_SINCE_MODEL | MESSAGE | LAST_ERROR
 * (MODELS comma-joined; LAST_ERROR only when the call failed), then `done`. Exits non-zero (with a
 * message on stderr) when opening or closing fails or an OP is malformed. */
#include <frictionless.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* The next `:`-separated field of *s (NUL-terminated in place), or NULL when none is left. */
static char *field(char **s) {
    if (*s == NULL) return NULL;
    char *f = *s, *colon = strchr(f, ':');
    if (colon) {
        *colon = '\0';
        *s = colon + 1;
    } else {
        *s = NULL;
    }
    return f;
}

static void print(fl_status st, const fl_control_state *s) {
    const char *kind = fl_model_kind_name(s->model_kind);
    const char *ood = fl_ood_mode_name(s->ood_mode);
    printf("%s %u %u %.17g %.17g %.17g %s %s %s %s %u ", fl_status_name(st), s->control_status,
           s->joint_index, s->kfc, s->max_output_friction_nm, s->max_curr_a,
           s->compensation ? "on" : "off", ood ? ood : "?", s->model[0] ? s->model : "-",
           kind ? kind : "?", s->n_models);
    /* The names follow one another, each NUL-terminated; an empty one ends the list. */
    unsigned n = 0;
    for (const char *p = s->models; *p; p += strlen(p) + 1, n++) printf("%s%s", n ? "," : "", p);
    if (n != s->n_models) {
        fprintf(stderr, "models: %u names listed, n_models = %u\n", n, s->n_models);
        exit(1);
    }
    if (n == 0) printf("-");
    printf(" %llu %llu %llu | %s | %s\n", (unsigned long long)s->set_since_ns[FL_CONTROL_KEY_KFC],
           (unsigned long long)s->set_since_ns[FL_CONTROL_KEY_COMPENSATION],
           (unsigned long long)s->set_since_ns[FL_CONTROL_KEY_MODEL], s->message,
           st == FL_STATUS_OK ? "" : fl_last_error());
}

int main(int argc, char **argv) {
    if (argc < 4) {
        fprintf(stderr, "usage: control PREFIX ROOT_PATH TIMEOUT_MS OP...\n");
        return 2;
    }
    fl_control *c = NULL;
    fl_status st = fl_control_open(argv[1], argv[2], (uint32_t)strtoul(argv[3], NULL, 10), &c);
    if (st != FL_STATUS_OK) {
        fprintf(stderr, "fl_control_open -> %s: %s\n", fl_status_name(st), fl_last_error());
        return 1;
    }
    for (int i = 4; i < argc; i++) {
        char *rest = argv[i];
        const char *op = field(&rest), *joint = field(&rest);
        fl_control_state s;
        memset(&s, 0, sizeof s);
        if (op && joint && strcmp(op, "get") == 0 && rest == NULL) {
            st = fl_control_get(c, joint, &s);
        } else if (op && joint && strcmp(op, "set") == 0) {
            const char *key = field(&rest), *value = rest;
            if (key == NULL || value == NULL) {
                fprintf(stderr, "`%s`: expected set:JOINT:KEY:VALUE\n", argv[i]);
                return 2;
            }
            st = fl_control_set(c, joint, key, value, &s);
        } else {
            fprintf(stderr, "`%s`: expected get:JOINT or set:JOINT:KEY:VALUE\n", argv[i]);
            return 2;
        }
        print(st, &s);
    }
    st = fl_control_close(c);
    if (st != FL_STATUS_OK) {
        fprintf(stderr, "fl_control_close -> %s: %s\n", fl_status_name(st), fl_last_error());
        return 1;
    }
    printf("done\n");
    return 0;
}
