/*  plunit tests of the platform's error messages (platform_errors.pl):
    a connection error prints as one readable line whatever its context,
    bound, partly bound (context(_, _), as a catcher that matches
    error(F, context(_, _)) leaves it) or unbound; never an
    `EXCEPTION while printing message`.
    Run: swipl -g run_tests -t halt test_platform_errors.pl
*/
:- use_module('../../platform_pl/platform_errors').
:- use_module('../../platform_pl/node').
:- use_module('../../platform_pl/messages').
:- use_module(library(plunit)).
:- use_module(library(socket)).

%   printed(+Error, -Text): Error as print_message(error, Error) prints it.
printed(Error, Text) :-
    message_to_codes(Error, Codes),
    string_codes(Text, Codes).

message_to_codes(Error, Codes) :-
    '$messages':translate_message(Error, Lines, []),
    with_output_to(codes(Codes), print_message_lines(current_output, '', Lines)).

%   A real refused connection: a port that was bound and closed again.
closed_port(Port) :-
    tcp_socket(S),
    tcp_bind(S, '127.0.0.1':Port),
    tcp_close_socket(S).

connect_error(Port, E) :-
    catch(agent_post('127.0.0.1':Port, nobody, hello, x, []), E, true),
    nonvar(E).

clean(Text) :-
    \+ sub_string(Text, _, _, _, "EXCEPTION"),
    \+ sub_string(Text, _, _, _, "weakest token"),
    \+ sub_string(Text, _, _, _, "(at _"),
    sub_string(Text, _, _, _, "cannot connect").

:- begin_tests(platform_errors).

test(connect_error_unbound_context) :-
    closed_port(Port),
    connect_error(Port, E),
    E = error(transport_error(_, connect(_)), Ctx),
    assertion(var(Ctx)),
    printed(E, Text),
    assertion(clean(Text)).

test(connect_error_partial_context) :-
    closed_port(Port),
    catch(agent_post('127.0.0.1':Port, nobody, hello, x, []),
          error(Formal, context(Pred, Msg)), true),
    assertion(var(Pred)), assertion(var(Msg)),
    printed(error(Formal, context(Pred, Msg)), Text),
    assertion(clean(Text)).

test(connect_error_remote_unbound) :-
    printed(error(transport_error(a:1, connect(refused)), remote(_)), Text),
    assertion(clean(Text)).

test(message_text_partial_context) :-
    message_text(error(transport_error(a:1, connect(refused)), context(_, _)), Text),
    assertion(clean(Text)).

test(weak_secret_context_still_explained) :-
    printed(error(permission_error(listen, address, '0.0.0.0':7001),
                  context(node_start/3, weak_secret(13, 128))), Text),
    assertion(sub_string(Text, _, _, _, "13 bits")),
    assertion(sub_string(Text, _, _, _, "needs 128")).

test(remote_context_still_named) :-
    printed(error(existence_error(agent, nobody), remote('127.0.0.1':7002)), Text),
    assertion(sub_string(Text, _, _, _, "(at 127.0.0.1:7002)")).

:- end_tests(platform_errors).
