/*  plunit tests of the Tartarus toplevel patterns (issue 12): list_agents/1
    with a link prints (or prints the error), isexist_agent/3 with unbound
    link and handler asks the local platform, help/1 finds the dFRL agent's
    aggregation hooks.
*/
:- use_module('../../platform_pl/tartarus').
:- use_module('../../platform_pl/dfrl_agent/dfrl_agent').
:- use_module(library(plunit)).

:- dynamic tt_handler/3.
tt_handler(guid, _, main).

:- begin_tests(tartarus_toplevel).

test(list_agents_of_a_link_prints_them, [cleanup(close_tartarus)]) :-
    start_tartarus(localhost, 0, 7),
    get_tartarus_details(Ip, Port),
    create_mobile_agent(a1, (Ip, Port), tt_handler, [7]),
    with_output_to(string(S), list_agents((Ip, Port))),
    assertion(sub_string(S, _, _, _, "Agents on ")),
    assertion(sub_string(S, _, _, _, "a1")),
    assertion(sub_string(S, _, _, _, "handler tt_handler")),
    list_agents(Names),
    assertion(Names == [a1]).

test(list_agents_of_an_unreachable_link_prints_the_error, [cleanup(close_tartarus)]) :-
    start_tartarus(localhost, 0, 7),
    with_output_to(string(S), list_agents((localhost, 1))),
    assertion(sub_string(S, _, _, _, "cannot list them")),
    assertion(sub_string(S, _, _, _, "cannot connect")).

test(list_agents_bad_link, [error(type_error(link, foo)), cleanup(close_tartarus)]) :-
    start_tartarus(localhost, 0, 7),
    list_agents(foo).

test(isexist_agent_unbound_link_and_handler, [cleanup(close_tartarus)]) :-
    start_tartarus(localhost, 0, 7),
    get_tartarus_details(Ip, Port),
    create_mobile_agent(a1, (Ip, Port), tt_handler, [7]),
    isexist_agent(a1, Link, Handler),
    assertion(Link == (Ip, Port)),
    assertion(Handler == tt_handler),
    assertion(isexist_agent(a1, (Ip, Port), _)),
    assertion(\+ isexist_agent(nobody, _, _)),
    findall(N, isexist_agent(N, _, _), All),
    assertion(All == [a1]).

test(help_finds_the_aggregation_hooks) :-
    forall(member(Hook-Text, [aggregate_init-"start the aggregate",
                              aggregate_step-"fold the Table",
                              aggregate_final-"writes back",
                              method_uses_visits-"visit"]),
           ( with_output_to(string(S), help(Hook)),
             assertion(sub_string(S, _, _, _, Text)) )).

:- end_tests(tartarus_toplevel).
