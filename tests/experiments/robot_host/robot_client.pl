/*  A plain swipl client of a `dfrl robot` service, for the tests.

    swipl robot_client.pl HOST PORT TOKEN

Reads JSON lines on stdin, one request each, in the console's form (contract K5):
{"share": {"robot": R, "round": N}} instead sends an agent from a node of this
client that reads R's table and writes it back with round(N), agent(sharer),
epoch(0) (a share, as the dFRL agent makes them); the robot's status shows it.
"status", "start", "stop", "files", {"configure": TEXT},
{"fetch": {"name": N, "offset": O, "max": M}}, or {"raw": TEXT} (a request
given as Prolog text, for malformed requests). Sends each as dfrl_robot(R)
with transport_request/4 (proving TOKEN, unless TOKEN is `none`) and prints
one JSON line: {"ok": Result} or {"error": Formal, "message": Text}.
*/
:- use_module('../../../platform_pl/tartarus').
:- use_module('../../../platform_pl/transport', [transport_request/4]).
:- use_module(library(http/json)).
:- use_module('../../../pybridge/robot_service', []).   % its error messages

:- initialization(main, main).

main :-
    current_prolog_flag(argv, [Host, PortText, TokenText]),
    atom_number(PortText, Port),
    token_options(TokenText, Options),
    set_stream(user_output, encoding(utf8)),
    repeat,
    read_line_to_string(user_input, Line),
    (   Line == end_of_file
    ->  !
    ;   Line == ""
    ->  fail
    ;   setup_call_cleanup(open_string(Line, In),
                           json_read(In, Json, [value_string_as(string)]),
                           close(In)),
        answer(Host:Port, Json, Options),
        fail
    ).

token_options(none, [reply_timeout(60)]) :- !.
token_options(Text, [tokens([Token]), reply_timeout(60)]) :-
    (   atom_number(Text, Token), integer(Token)
    ->  true
    ;   Token = Text
    ).

answer(Host:Port, json([share=json(Args)]), Options) :-
    !,
    memberchk(robot=R, Args),
    memberchk(round=N, Args),
    atom_string(Robot, R),
    memberchk(tokens([Token]), Options),
    (   catch(current_node(_), _, fail)
    ->  true
    ;   start_tartarus('127.0.0.1', 0, Token)
    ),
    random_between(1, 1000000000, Salt),
    format(atom(Name), 'sharer_~w_~w', [N, Salt]),
    create_mobile_agent(Name, sharer, [Token]),
    assertz(share_at(Name, Port, Robot, N)),
    add_payload(Name, [(share_at, 4)]),
    move_agent(Name, (Host, Port)),
    format("{\"ok\": true}~n"),
    flush_output.
answer(Address, Json, Options) :-
    catch(( request(Json, Request),
            transport_request(Address, dfrl_robot(Request), Result, Options),
            result_json(Result, Out),
            Reply = json([ok=Out])
          ),
          error(Formal, _),
          ( format(string(F), '~q', [Formal]),
            message_to_codes(error(Formal, _), Codes),
            string_codes(M, Codes),
            Reply = json([error=F, message=M])
          )),
    with_output_to(string(S), json_write_dict(current_output, Reply, [width(0)])),
    format("~s~n", [S]),
    flush_output.

request(Name, Request) :-
    string(Name), !,
    atom_string(Request, Name).
request(json([configure=Text]), configure(Text)) :- !.
request(json([fetch=json(Args)]), fetch(Name, Offset, Max)) :- !,
    memberchk(name=Name, Args),
    memberchk(offset=Offset, Args),
    memberchk(max=Max, Args).
request(json([raw=Text]), Request) :- !,
    term_string(Request, Text).

%   The share agent (handler sharer/3, payload share_at/4).
:- dynamic sharer/3, share_at/4.

sharer(guid, (_, Port), main) :-
    share_at(guid, Port, Robot, Round),
    !,
    robot_resources:get_robot_table(Robot, T, [timeout(20)]),
    robot_resources:set_robot_table(Robot, T, [timeout(20), round(Round), agent(sharer), epoch(0)]).
sharer(guid, _, main).

result_json(D, D) :- is_dict(D), !.
result_json(true, true) :- !.
result_json(chunk(Data, Eof), json([data=Data, eof=Eof])) :- !.
result_json(Files, List) :-
    is_list(Files), !,
    findall([N, S], member(file(N, S), Files), List).
result_json(Other, S) :-
    format(string(S), '~q', [Other]).

message_to_codes(Term, Codes) :-
    '$messages':translate_message(Term, Lines, []),
    with_output_to(codes(Codes), print_message_lines(current_output, '', Lines)).
