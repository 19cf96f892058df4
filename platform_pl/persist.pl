:- module(persist,
          [ agent_save/3,               % +Node, +Name, +File
            node_save_state/2,          % +Node, +File
            node_load_state/2           % +Node, +File
          ]).
:- use_module(agents).
:- use_module(node, [node_property/2]).
:- autoload(library(error), [must_be/2]).
:- autoload(library(listing), [portray_clause/2]).

/** <module> Saving agents and platform state to files

agent_save/3 writes an agent as readable Prolog: a comment header with
its properties and its clauses, as portray_clause/2 prints them (the
agent's name in place of `guid`).

node_save_state/2 writes every agent of a node as one term
dfrl_agent(Status, Record) per agent, canonical, so node_load_state/2 can
reinstall them (idle, not running) on the same or another node.

Tokens are never written: a saved agent's record holds [] and a loaded
agent takes the tokens of the node it is loaded into (as an agent that
arrives by migration does).
*/

%!  agent_save(+Node, +Name, +File) is det.

agent_save(Node, Name, File) :-
    agent_export(Node, Name, agent(Name, Handler, Kind, _Tokens, Payload,
                                   _Preds, Clauses, _Hops)),
    setup_call_cleanup(
        open(File, write, Out, [encoding(utf8)]),
        ( format(Out, '% dfrl agent ~q~n', [Name]),
          format(Out, '%   handler: ~q, kind: ~q~n', [Handler, Kind]),
          format(Out, '%   payload: ~q~n~n', [Payload]),
          forall(member(Cl, Clauses), portray_clause(Out, Cl))
        ),
        close(Out)).

%!  node_save_state(+Node, +File) is det.

node_save_state(Node, File) :-
    findall(Status-Record,
            ( agent_exists(Node, Name),
              agent_status(Node, Name, Status),
              agent_export(Node, Name, Record),
              setarg(4, Record, [])
            ),
            Agents),
    setup_call_cleanup(
        open(File, write, Out, [encoding(utf8)]),
        ( format(Out, '% dfrl platform state of ~w~n', [Node]),
          forall(member(S-R, Agents),
                 format(Out, '~k.~n', [dfrl_agent(S, R)]))
        ),
        close(Out)).

%!  node_load_state(+Node, +File) is det.
%
%   Install the agents saved in File on Node, idle (and in the node's
%   custody store if it has one). Agents whose name is taken on Node are
%   skipped with a warning.

node_load_state(Node, File) :-
    must_be(atom, Node),
    setup_call_cleanup(
        open(File, read, In, [encoding(utf8)]),
        load_terms(Node, In),
        close(In)).

load_terms(Node, In) :-
    read_term(In, Term, []),
    (   Term == end_of_file
    ->  true
    ;   (   Term = dfrl_agent(_Status, Record)
        ->  node_property(Node, tokens(Tokens)),
            catch(( (   compound(Record), compound_name_arity(Record, agent, 8)
                    ->  setarg(4, Record, Tokens)
                    ;   true
                    ),
                    agent_install(Node, Record, idle, Name),
                    agent_notify(saved, Node, Name)     % held on disk too
                  ), E,
                  print_message(warning, E))
        ;   print_message(warning, format('Not a saved agent: ~p', [Term]))
        ),
        load_terms(Node, In)
    ).
